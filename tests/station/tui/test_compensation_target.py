"""The Compensation page with per-leg compensation targets: leg 1 compensated by the station, leg 2
by its drive (the simulated rig over Modbus on 127.0.0.1). The page names the targets, the push
confirmation names the leg's target, the push lands in the station's table store (not the drive),
the audit entries record the target, and the rollback restores the store's previous table.
A leg whose target is the controller is refused and logged, nothing written."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest
from textual.widgets import DataTable, Static

from procedures.compensation.audit import read_entries
from procedures.compensation.push import quantize, table_sha256
from station.tui.app import StationApp
from tests.station.tui.steps import connect_and_fit
from station.tui.screens.common import ConfirmScreen

pytestmark = pytest.mark.timeout(120)


def test_station_target_push_and_rollback_on_the_page(recorded_session, cfg, size, wait_until, notes, connected):
    cfg.compensation.legs = {1: "station", 3: "controller"}
    asyncio.run(_station_target(recorded_session, cfg, size, wait_until, notes, connected))


async def _station_target(path, cfg, size, wait_until, notes, connected):
    store = Path(cfg.recordings_dir) / "station-tables.json"
    audit_path = Path(cfg.recordings_dir) / "audit.jsonl"
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await connect_and_fit(pilot, wait_until, connected, path)
        await pilot.press("f4")
        comp = app.screen
        table = comp.query_one("#comp-table", DataTable)
        await wait_until(pilot, lambda: table.row_count == 2 and "pts" in str(table.get_row_at(1)[6]), 30, "the drives")
        source = str(comp.query_one("#comp-source", Static).render())
        assert "compensation target: leg 1 station, leg 3 controller" in source
        assert str(table.get_row_at(0)[6]).endswith("station") and not str(table.get_row_at(1)[6]).endswith("station")
        drive1 = app.rig.axes[1].inner  # the drive under the station's table
        drive_sha = table_sha256(drive1.read_table(drive1.active_bank()))
        # push leg 1: the confirmation names the target, the table lands in the station's store
        await pilot.press("u")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the push confirmation")
        question = str(app.screen.query_one("#confirm-question").render())
        assert "compensation target station" in question and "target:   station" in question
        await pilot.press("y")
        await wait_until(pilot, lambda: any(n.startswith("pushed: leg 1 bank ") for n in notes(app)), 30, "the push")
        want = table_sha256(quantize(comp.table.legs[1].to_bank(), 0.001))
        leg1 = json.loads(store.read_text())["legs"]["1"]
        assert leg1["active_bank"] == 1 and leg1["banks"][1]["sha256"] == want
        assert table_sha256(drive1.read_table(drive1.active_bank())) == drive_sha  # the drive's own table untouched
        entries, problems = read_entries(audit_path)
        assert not problems
        assert [(e.action, e.outcome, e.details["target"]) for e in entries] == [
            ("push", "started", "station"), ("push", "ok", "station")]
        # roll back: the store's previous (empty) table is active again
        await pilot.press("b")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the rollback confirmation")
        await pilot.press("y")
        await wait_until(pilot, lambda: any(n.startswith("rolled back: leg 1 bank ") for n in notes(app)), 30, "the rollback")
        leg1 = json.loads(store.read_text())["legs"]["1"]
        assert leg1["active_bank"] == 0 and leg1["banks"][0]["error_fwd_um"] == []
        entries, _ = read_entries(audit_path)
        assert [(e.action, e.outcome, e.details["target"]) for e in entries[-2:]] == [
            ("rollback", "started", "station"), ("rollback", "ok", "station")]


def test_controller_target_is_refused_on_the_page(recorded_session, cfg, size, wait_until, notes, connected):
    cfg.compensation.target = "controller"
    asyncio.run(_controller(recorded_session, cfg, size, wait_until, notes, connected))


async def _controller(path, cfg, size, wait_until, notes, connected):
    audit_path = Path(cfg.recordings_dir) / "audit.jsonl"
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await connect_and_fit(pilot, wait_until, connected, path)
        await pilot.press("f4")
        table = app.screen.query_one("#comp-table", DataTable)
        await wait_until(pilot, lambda: table.row_count == 2, 30, "the table")
        bank = app.rig.axes[1].active_bank()
        await pilot.press("u")
        await wait_until(pilot, lambda: any("compensation target is controller" in n for n in notes(app)), 30,
                         "the refusal")
        assert not isinstance(app.screen, ConfirmScreen)
        assert app.rig.axes[1].active_bank() == bank
        entries, _ = read_entries(audit_path)
        assert [(e.action, e.outcome) for e in entries] == [("push", "refused")]
