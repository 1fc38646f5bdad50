"""Sweep flows through the UI on the simulated rig at time scale 0 (real Modbus TCP + serial pty).

The recording is written by station.services.jobs.run_sweep (the CLI's runner); these tests check what
the operator sees (plot, progress, state) and what is left behind (drives, recording).
"""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from textual.widgets import Input, ProgressBar

from procedures.io.recording.reader import read_session
from station.tui.app import StationApp
from station.tui.screens.common import ConfirmScreen
from station.tui.widgets import XYPlot
from tests.station.tui.steps import choose_plan, press_to_quit


pytestmark = pytest.mark.timeout(120)


async def fill_form(pilot, **fields) -> None:
    """Set sweep form fields by id (legs, plan, cycles, n-targets, step, min-mm, max-mm, dwell);
    the plan first, since choosing a plan sets its standard number of cycles."""
    app = pilot.app
    if "plan" in fields:
        await choose_plan(pilot, fields.pop("plan"))
    for wid, value in fields.items():
        wid = wid.replace("_", "-")
        app.screen.query_one(f"#{wid}", Input).value = str(value)


async def start_sweep(pilot, connected, wait_until, **fields) -> None:
    app = pilot.app
    await connected(pilot)
    await pilot.press("f2")
    await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep screen")
    await fill_form(pilot, **fields)
    await pilot.pause()
    await pilot.click("#start")
    await wait_until(pilot, lambda: app.sweep.status != "idle", what="the sweep to start")


def plot(app) -> XYPlot:
    return app.screen.query_one("#sweep-plot", XYPlot)


def test_sweep_completes_with_plot_progress_and_recording(cfg, size, connected, wait_until):
    asyncio.run(_test_sweep_completes_with_plot_progress_and_recording(cfg, size, connected, wait_until))


async def _test_sweep_completes_with_plot_progress_and_recording(cfg, size, connected, wait_until):
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await start_sweep(pilot, connected, wait_until, legs="3", cycles=2, n_targets=6)
        await wait_until(pilot, lambda: app.sweep.status == "completed", what="the sweep to complete")
        total = 2 * 2 * 6
        assert app.sweep.done == app.sweep.total == total
        # the screen shows every point, split by direction, and a full progress bar
        await wait_until(pilot, lambda: plot(app).drawn_points == total, what="the plot to show every point")
        assert plot(app).drawn_series == ["approach +1 (up)", "approach −1 (down)"]
        bar = app.screen.query_one("#progress", ProgressBar)
        assert bar.progress == bar.total == total
        trace = app.sweep.traces[3]
        assert len(trace.up_target_mm) == len(trace.down_target_mm) == total // 2
        # the recording is complete and is what the plot showed
        out = app.sweep.out
        s = read_session(out)
        assert s.attrs["outcome"] == "completed"
        assert sorted(s.points["index"]) == list(range(total))
        assert set(s.points["leg"]) == {3}
        up = s.points[s.points["direction"] == 1]
        np.testing.assert_allclose(up["error_um"], trace.up_error_um)
        assert app.last_session == out
        # the sweep leaves the drive disabled and still
        st = app.rig.axes[3].status()
        assert not st.enabled and not st.moving
        await press_to_quit(pilot, "ctrl+q")  # no sweep running: quits without asking
    assert app.return_code == 0


def test_plot_and_progress_advance_live_and_pause_holds_motion(cfg, size, connected, wait_until):
    asyncio.run(_test_plot_and_progress_advance_live_and_pause_holds_motion(cfg, size, connected, wait_until))


async def _test_plot_and_progress_advance_live_and_pause_holds_motion(cfg, size, connected, wait_until):
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        # 6 x 4332 points: longer than the test (its pause, resume and abort), whatever the machine
        await start_sweep(pilot, connected, wait_until, legs="1-6", plan="paper")
        bar = app.screen.query_one("#progress", ProgressBar)
        await wait_until(pilot, lambda: plot(app).drawn_points >= 3 and bar.progress >= 3, what="first points on screen")
        first_plot, first_bar = plot(app).drawn_points, bar.progress
        await wait_until(pilot, lambda: plot(app).drawn_points >= first_plot + 20, what="the plot to advance")
        assert bar.progress > first_bar and bar.total == 6 * 2 * 6 * 361
        # pause: the run holds between points and the drive is not moving
        await pilot.press("p")
        await wait_until(pilot, lambda: app.sweep.status == "paused", what="the pause")
        held = app.sweep.done
        st = app.rig.axes[1].status()
        assert not st.moving
        for _ in range(10):  # a few UI frames: nothing is measured while paused
            await pilot.pause()
        assert app.sweep.done == held and app.sweep.status == "paused"
        await pilot.press("p")
        await wait_until(pilot, lambda: app.sweep.done > held + 5, what="the sweep to resume")
        await pilot.press("a")
        await wait_until(pilot, lambda: not app.sweep.active, what="the abort")
        assert app.sweep.status == "aborted"


def test_abort_mid_sweep_stops_drives_and_keeps_a_valid_recording(cfg, size, connected, wait_until):
    asyncio.run(_test_abort_mid_sweep_stops_drives_and_keeps_a_valid_recording(cfg, size, connected, wait_until))


async def _test_abort_mid_sweep_stops_drives_and_keeps_a_valid_recording(cfg, size, connected, wait_until):
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await start_sweep(pilot, connected, wait_until, legs="1", plan="paper")
        await wait_until(pilot, lambda: app.sweep.done >= 10, what="ten points")
        await pilot.press("a")
        await wait_until(pilot, lambda: not app.sweep.active, what="the abort to finish")
        assert app.sweep.status == "aborted"
        done = app.sweep.done
        assert 10 <= done < app.sweep.total
        st = app.rig.axes[1].status()
        assert not st.moving and not st.enabled, st
        assert app.rig.sim.drive_server.state(1) != "operation_enabled"
        s = read_session(app.sweep.out)
        assert s.attrs["outcome"] == "aborted"
        # every measured point is on disk, in plan order, none twice
        assert list(s.points["index"]) == list(range(done))
        assert np.all(np.isfinite(s.points["error_um"]))


def test_quit_during_a_sweep_asks_then_aborts_and_keeps_the_recording(cfg, size, connected, wait_until):
    asyncio.run(_test_quit_during_a_sweep_asks_then_aborts_and_keeps_the_recording(cfg, size, connected, wait_until))


async def _test_quit_during_a_sweep_asks_then_aborts_and_keeps_the_recording(cfg, size, connected, wait_until):
    # a few ms per point: at time scale 0 the plan's 4332 points can end while a question is open
    app = StationApp(cfg, time_scale=0.005)
    async with app.run_test(size=size) as pilot:
        await start_sweep(pilot, connected, wait_until, legs="4", plan="paper")
        await wait_until(pilot, lambda: app.sweep.done >= 3, what="first points")
        await pilot.press("ctrl+q")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="the quit question")
        await pilot.press("n")  # keep sweeping
        await wait_until(pilot, lambda: not isinstance(app.screen, ConfirmScreen), what="the dialog to close")
        assert app.sweep.active
        before = app.sweep.done
        await wait_until(pilot, lambda: app.sweep.done > before, what="the sweep to go on")
        await pilot.press("ctrl+q")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="the quit question")
        sim = app.rig.sim
        await press_to_quit(pilot, "y")
    assert app.sweep.status == "aborted"
    s = read_session(app.sweep.out)
    assert s.attrs["outcome"] == "aborted"
    assert len(s.points) == app.sweep.done > before
    assert sim.drive_server.state(4) != "operation_enabled"


@pytest.mark.timeout(300)  # the module's 120 s is shorter than the 240 s this test gives the sweep to complete
def test_quit_confirmed_after_the_sweep_ended_meanwhile_quits(cfg, size, connected, wait_until):
    asyncio.run(_test_quit_confirmed_after_the_sweep_ended_meanwhile_quits(cfg, size, connected, wait_until))


async def _test_quit_confirmed_after_the_sweep_ended_meanwhile_quits(cfg, size, connected, wait_until):
    """The question was asked while a sweep ran, the sweep ended before the answer: "abort and
    quit" then quits (it waited for a sweep end that had already come)."""
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await start_sweep(pilot, connected, wait_until, legs="3", plan="paper")  # 4332 points: seconds
        await wait_until(pilot, lambda: app.sweep.done >= 3, what="first points")
        await pilot.press("ctrl+q")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="the quit question")
        await wait_until(pilot, lambda: app.sweep.status == "completed", timeout_s=240, what="the sweep to complete")
        await press_to_quit(pilot, "y")
    assert app.sweep.status == "completed"
    assert len(read_session(app.sweep.out).points) == app.sweep.total
