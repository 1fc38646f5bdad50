"""A plan that cannot finish, on the Sweep page (issue 22, item 3): the page sizes it from the
form (nothing built) and asks with its figures before starting; Abort and Ctrl+Q end it within
2 s at any moment, while its plan is still being built too, and the drives are stopped.

The plan is the issue's: a step of 0.0001 mm over -90..90 mm, 18 000 010 points (its plan takes
seconds to build). Simulated rig at time scale 0 (real Modbus TCP + serial pty); the set-points
the drives latched are counted at the simulated drive server."""

from __future__ import annotations

import asyncio
import time

import pytest
from textual.widgets import Input, Static

from procedures.io.recording.reader import read_session
from station.tui.app import StationApp
from station.tui.screens.common import ConfirmScreen

pytestmark = pytest.mark.timeout(300)

END_WITHIN_S = 2.0


def confirm_text(app) -> str:
    return str(app.screen.query_one("#confirm-question").render())


async def huge_plan_asked(pilot, connected, wait_until) -> None:
    """Connect, go to the Sweep page, type the 0.0001 mm step, press Start: the question is on show."""
    app = pilot.app
    await connected(pilot)
    await pilot.press("f2")
    await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep page")
    app.screen.query_one("#step", Input).value = "0.0001"
    await wait_until(pilot, lambda: "18 000 010 points" in str(app.screen.query_one("#plan-summary", Static).render()),
                     what="the plan's size in the summary")
    app.screen.query_one("#start").focus()
    await pilot.press("s")
    await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the question")


def test_the_sweep_page_asks_with_the_figures_and_abort_ends_it_at_any_moment(cfg, size, connected, wait_until, notes):
    asyncio.run(_asks_then_aborts(cfg, size, connected, wait_until, notes))


async def _asks_then_aborts(cfg, size, connected, wait_until, notes):
    app = StationApp(cfg, time_scale=0.0, poll_interval_s=0.5)
    async with app.run_test(size=size) as pilot:
        await huge_plan_asked(pilot, connected, wait_until)
        text = confirm_text(app)
        assert "18 000 010 points" in text and "h (" in text and "GB session file" in text and "max_points" in text
        server = app.rig.sim.drive_server
        moves = server.set_points(1)
        await pilot.press("n")  # cancel: nothing starts
        await wait_until(pilot, lambda: not isinstance(app.screen, ConfirmScreen), what="the dialog to close")
        assert not app.sweep.active and app.sweep.status == "idle"

        # started, then aborted at once: while its plan is being built (a fraction of a second
        # here; tests/procedures/acquisition/test_plan_size.py aborts the building itself) or just after
        await pilot.press("s")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the question")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.sweep.active, what="the sweep to start")
        t0 = time.monotonic()
        await pilot.press("a")
        await wait_until(pilot, lambda: not app.sweep.active, 10, "the abort at its start")
        at_start_s = time.monotonic() - t0
        assert app.sweep.status == "aborted"
        if app.sweep.out.exists():  # it had begun: the recording is finished as aborted
            assert read_session(app.sweep.out).attrs["outcome"] == "aborted"
        else:  # caught while the plan was built: nothing moved, no resume of a file never written
            assert app.sweep.done == 0 and server.set_points(1) == moves
            assert any("aborted before it began; nothing moved, nothing recorded" in n for n in notes(app))
            assert not any("Finish it later" in n for n in notes(app))
        st = app.rig.axes[1].status()
        assert not st.moving and not st.enabled

        # started again and left to run: aborted while it measures
        app.clear_notifications()
        await pilot.press("s")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the question")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.sweep.done >= 5, 60, "the huge sweep's first points")
        t0 = time.monotonic()
        await pilot.press("a")
        await wait_until(pilot, lambda: not app.sweep.active, 10, "the abort of the running sweep")
        running_s = time.monotonic() - t0
        assert app.sweep.status == "aborted"
        st = app.rig.axes[1].status()
        assert not st.moving and not st.enabled
        assert read_session(app.sweep.out).attrs["outcome"] == "aborted"
        print(f"abort at the start: {at_start_s:.2f} s; during the sweep: {running_s:.2f} s")
        assert at_start_s < END_WITHIN_S and running_s < END_WITHIN_S


@pytest.mark.parametrize("when", ["building", "running"])
def test_ctrl_q_ends_a_huge_sweep_and_the_app_within_2_s(cfg, size, connected, wait_until, when):
    asyncio.run(_quits(cfg, size, connected, wait_until, when))


async def _quits(cfg, size, connected, wait_until, when):
    app = StationApp(cfg, time_scale=0.0, poll_interval_s=0.5)
    async with app.run_test(size=size) as pilot:
        await huge_plan_asked(pilot, connected, wait_until)
        await pilot.press("y")
        if when == "running":
            await wait_until(pilot, lambda: app.sweep.done >= 5, 60, "the huge sweep's first points")
        else:
            await wait_until(pilot, lambda: app.sweep.active, what="the sweep to start")
        sim = app.rig.sim
        await pilot.press("ctrl+q")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the quit question")
        if when == "running":
            assert "station sweep --resume" in confirm_text(app)
        t0 = time.monotonic()
        await pilot.press("y")
        await wait_until(pilot, lambda: not app.is_running, 10, "the app to exit")
        quit_s = time.monotonic() - t0
    print(f"ctrl+q while {when}: the app ended {quit_s:.2f} s after the yes")
    assert quit_s < END_WITHIN_S
    assert app.sweep.status == "aborted"
    assert sim.drive_server.state(1) != "operation_enabled"
    if app.sweep.out.exists():  # it had begun (always, when "running")
        assert read_session(app.sweep.out).attrs["outcome"] == "aborted"
    else:
        assert when == "building" and app.sweep.done == 0
