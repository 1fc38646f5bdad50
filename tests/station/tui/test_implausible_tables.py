"""The Compensation page makes and pushes tables through the same unit-slip checks as `station table`
and `station push` (station.services.table_jobs): a model whose corrections are far beyond the error
it was fitted to (as if its error had been read in the wrong unit) gives a table that is refused on
the page, and its push (corrections beyond 100 um, most likely nm) is refused and logged with the
drive's table and bank untouched (the simulated rig: a real Modbus server on 127.0.0.1). Each is
accepted only through a confirmation dialog, which the command line's --accept-implausible stands for."""

from __future__ import annotations

import asyncio
from dataclasses import replace
from pathlib import Path

import pytest
from textual.widgets import Static

from procedures.compensation.audit import read_entries
from procedures.compensation.push import quantize, table_sha256
from station.tui.app import StationApp
from station.tui.screens.common import ConfirmScreen
from tests.station.tui.steps import connect_and_fit
from tests.tooling import slipped_model

pytestmark = pytest.mark.timeout(120)


def test_an_implausible_table_and_push_are_refused_then_accepted_by_confirmation(recorded_session, cfg, size,
                                                                                 wait_until, notes, connected):
    asyncio.run(_implausible(recorded_session, cfg, size, wait_until, notes, connected))


def _question(app) -> str:
    # a dialog a rig key opens comes a moment after the key (StationScreen.RIG_KEYS): "" until composed
    questions = app.screen.query("#confirm-question") if isinstance(app.screen, ConfirmScreen) else []
    return str(questions.first().render()) if questions else ""


def _held(app) -> tuple[int, str]:
    """Leg 1's active bank and the sha256 of the table in it, read from the drive."""
    with app.rig_lock:
        axis = app.rig.axes[1]
        bank = axis.active_bank()
        return bank, table_sha256(axis.read_table(bank))


async def _implausible(path, cfg, size, wait_until, notes, connected):
    audit_path = Path(cfg.recordings_dir) / "audit.jsonl"
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await connect_and_fit(pilot, wait_until, connected, path)
        app.analysis = replace(app.analysis, model=slipped_model(app.analysis.model))
        before = _held(app)
        # the page makes the table on arrival: refused, said on the page, and a dialog offers to accept it
        await pilot.press("f4")
        await wait_until(pilot, lambda: "Make this table anyway?" in _question(app), 30, "the table's refusal")
        comp = next(s for s in app.screen_stack if getattr(s, "MODE", "") == "compensation")  # under the dialog
        status = comp.query_one("#comp-status", Static)
        assert "leg 1: correction span (um) = " in _question(app)
        assert comp.table is None
        shown = str(status.render())
        assert shown.startswith("table refused: leg 1: correction span (um) = ") and "larger than the error" in shown
        assert "confirm it in the dialog that follows if the values are right" in shown
        assert any(n.startswith("leg 1: correction span (um) = ") for n in notes(app))
        await pilot.press("n")  # cancelled: still no table
        await wait_until(pilot, lambda: app.screen is comp, what="the dialog closed")
        assert comp.table is None
        # made again, and accepted: the table is there, with the warning on the page
        await pilot.click("#comp-make")
        await wait_until(pilot, lambda: "Make this table anyway?" in _question(app), 30, "the dialog again")
        await pilot.press("y")
        await wait_until(pilot, lambda: comp.table is not None, 30, "the accepted table")
        assert "(kept: confirmed in the dialog)" in str(status.render())
        assert max(abs(v) for v in comp.table.legs[1].error_fwd_um) > 100.0
        # its push: refused by the push job before the drive is written, logged, and offered again
        await pilot.press("u")
        await wait_until(pilot, lambda: "Push anyway?" in _question(app), 30, "the push's refusal")
        # the notice says the refusal in the push job's own words (those `station push` prints)
        refusal = next((n for n in notes(app)
                        if n.startswith(f"the table of the default model of {Path(path).name}, leg 1, point ")), "")
        assert refusal, notes(app)
        assert "looks like nm in an um field" in refusal and "not 100 um and more" in refusal
        assert refusal.endswith("confirm it in the dialog that follows if the values are right. "
                                "Nothing was written to the drive.")
        assert "looks like nm in an um field" in str(status.render())
        assert _held(app) == before
        entries = read_entries(audit_path)[0]
        assert [(e.action, e.leg, e.outcome) for e in entries] == [("push", 1, "refused")]
        assert entries[0].message == refusal
        # pushed anyway: the usual push confirmation follows, and only its yes writes the drive
        await pilot.press("y")
        await wait_until(pilot, lambda: "Push this table to leg 1" in _question(app), 30, "the push confirmation")
        assert len(read_entries(audit_path)[0]) == 1  # (the push holds the rig while it asks)
        await pilot.press("y")
        await wait_until(pilot, lambda: any(n.startswith("pushed: leg 1 bank ") for n in notes(app)), 30, "the push")
        bank, sha = _held(app)
        assert bank != before[0] and sha == table_sha256(quantize(comp.table.legs[1].to_bank(), app.rig.axes[1].table_spec()))
        entries = read_entries(audit_path)[0]
        assert [(e.leg, e.outcome) for e in entries] == [(1, "refused"), (1, "started"), (1, "ok")]
        assert "looks like nm" in entries[-1].source["implausible_accepted"][0]


def test_a_table_from_a_model_worse_on_held_out_data_asks_first(recorded_session, cfg, size, wait_until, notes,
                                                                 connected):
    """As `station table` asks at a terminal (issue 31): a negative held-out range reduction."""
    asyncio.run(_worse_held_out(recorded_session, cfg, size, wait_until, connected))


async def _worse_held_out(path, cfg, size, wait_until, connected):
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await connect_and_fit(pilot, wait_until, connected, path)
        leg = app.analysis.model.legs[1]
        leg.stats = replace(leg.stats, heldout_range_um=leg.stats.range_before_um * 1.25)  # a reduction of -25 %
        await pilot.press("f4")
        await wait_until(pilot, lambda: "Make this table anyway?" in _question(app), 30, "the table's refusal")
        comp = next(s for s in app.screen_stack if getattr(s, "MODE", "") == "compensation")
        assert "leg 1: held-out range reduction (%) = -25: the model made the leg's error worse" in _question(app)
        assert comp.table is None
        await pilot.press("y")
        await wait_until(pilot, lambda: comp.table is not None, 30, "the accepted table")
        assert "(kept: confirmed in the dialog)" in str(comp.query_one("#comp-status", Static).render())
