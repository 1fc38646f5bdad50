"""A sweep of a compensated leg in the terminal UI (issue 31.7): a table pushed to leg 1 of the
simulated rig the app holds (through the real Modbus push), then a sweep started on the Sweep
page (F2) asks first, the question of station.services.jobs.check_compensation (the one `station
sweep` asks or needs --yes for). Cancel: nothing moves, nothing is recorded. Yes: the session
records the active table and is stage "other", not an as-found calibration."""

from __future__ import annotations

import asyncio

import pytest

from station.services.table_jobs import push_table
from procedures.compensation.table import LegTable
from procedures.io.recording.reader import read_session
from procedures.io.recording.stage import active_tables
from station.tui.app import StationApp
from station.tui.screens.common import ConfirmScreen
from tests.station.tui.test_sweep_flow import fill_form

pytestmark = pytest.mark.timeout(120)


def test_sweep_of_a_compensated_leg_asks_first(cfg, size, connected, wait_until, notes):
    asyncio.run(_test(cfg, size, connected, wait_until, notes))


async def _start(pilot, wait_until) -> None:
    app = pilot.app
    await fill_form(pilot, legs="1", cycles=2, n_targets=5)
    await pilot.pause()
    await pilot.click("#start")
    await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="the question on the compensated leg")


async def _test(cfg, size, connected, wait_until, notes):
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        x = [-90.0 + 15.0 * i for i in range(13)]
        pushed = push_table(app.rig.axes[1], LegTable(1, -90.0, 15.0, tuple(0.01 * v for v in x),
                                                      tuple(0.01 * v + 0.5 for v in x)))
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep screen")

        await _start(pilot, wait_until)
        question = str(app.screen.question)
        assert "A compensation table is active (leg 1: bank" in question and "13 points" in question
        assert "stage 'other'" in question
        await pilot.press("n")  # Cancel
        await wait_until(pilot, lambda: not app.sweep.active, what="the refused sweep to end")
        assert app.sweep.done == 0 and not app.sweep.out.exists()  # nothing moved, nothing recorded
        assert any("a compensation table is active" in n and "nothing moved" in n for n in notes(app))

        app.clear_notifications()  # the refusal's notification lies over the Start button
        await _start(pilot, wait_until)
        await pilot.press("y")
        await wait_until(pilot, lambda: app.sweep.status == "completed", what="the compensated sweep to complete")
        s = read_session(app.sweep.out)
        assert s.stage == "other" and s.attrs["stage"] == "other"
        assert list(active_tables(s.devices)) == [1] and "13 points from -90.000 mm" in active_tables(s.devices)[1]
        assert f"bank {pushed.bank} active" in active_tables(s.devices)[1]
