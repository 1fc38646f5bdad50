"""Resuming an aborted sweep from the Sweep page (r): the same job as `station sweep --resume`
(station.services.jobs.resumable_plan, then run_sweep(resume=True)), appending to the same file;
refusals (complete, no plan, missing, a sweep running) are notifications. Simulated rig (real
Modbus TCP + serial pty) at time scale 0.02, so a sweep in the UI lasts long enough to act on."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from textual.widgets import Input, Select, Static

from procedures.engine import events as ev
from procedures.engine.control import RunControl
from procedures.acquisition.plans import iso230_plan
from procedures.io.recording.reader import read_session
from procedures.engine.runner import CallbackSink
from tests.tooling import start_paper_sweep
from station.services.config import StationConfig
from station.services.jobs import run_sweep
from station.tui.app import StationApp
from station.tui.screens.sweep import ResumeScreen

pytestmark = pytest.mark.timeout(180)


def status_text(app) -> str:
    return str(app.screen.query_one("#sweep-status", Static).render())


def aborted_session(path, legs=(2,), after: int = 4):
    """A session of `legs` (5 targets -80..80 mm, 1 cycle: 10 points a leg) aborted after `after` points."""
    plan = iso230_plan(legs, -80.0, 80.0, step_mm=40.0, cycles=1)
    control = RunControl()

    def on_event(e):
        if isinstance(e, ev.PointMeasured) and e.done == after:
            control.abort("test abort")

    from station.services.wiring import open_rig

    cfg = StationConfig(operator="test")
    with open_rig(cfg, legs=legs, time_scale=0.0) as rig:
        result = run_sweep(rig, plan, path, cfg, sinks=[CallbackSink(on_event)], control=control)
    assert result.outcome == "aborted" and result.points == after
    return path, plan


async def open_resume(pilot, wait_until) -> ResumeScreen:
    app = pilot.app
    await pilot.press("r")
    await wait_until(pilot, lambda: isinstance(app.screen, ResumeScreen), what="the resume dialog")
    # settled: its path field focused (what Enter submits) and its buttons laid out (where a click
    # lands); a fixed 0.1 s was not that under load
    await wait_until(pilot, lambda: app.screen.query("#resume-path") and app.focused is app.screen.query_one("#resume-path")
                     and app.screen.query_one("#resume-yes").region.area > 0, what="the resume dialog settled")
    return app.screen


def test_r_resumes_the_aborted_sweep_into_the_same_file(cfg, size, connected, wait_until):
    asyncio.run(_resume_the_aborted_one(cfg, size, connected, wait_until))


async def _resume_the_aborted_one(cfg, size, connected, wait_until):
    # 1 simulated s = 20 ms: the paper plan (dwell 1 s a point) runs for minutes, long enough to act
    app = StationApp(cfg, time_scale=0.02, hide_volatile=True)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep page")
        await start_paper_sweep(pilot, "1")
        await wait_until(pilot, lambda: app.sweep.done >= 10, what="ten points")
        await pilot.press("a")
        await wait_until(pilot, lambda: app.sweep.status == "aborted", what="the abort")
        out, first = app.sweep.out, app.sweep.done
        session_id = read_session(out).attrs["session_id"]
        assert any("r on the Sweep page" in n.message for n in app._notifications)

        # r offers the aborted session; Enter resumes it
        dialog = await open_resume(pilot, wait_until)
        path = dialog.query_one("#resume-path", Input)
        assert path.value == str(out)
        # a session chosen in the list goes into the path; the choice cleared (nothing chosen)
        # leaves the path as it is (it once became the text "Select.NULL")
        listed = dialog.query_one("#resume-list", Select)
        listed.value = str(out)  # (refused by the Select if the list did not offer it)
        path.value = ""
        await wait_until(pilot, lambda: path.value == str(out), what="the chosen session in the path")
        listed.clear()
        await wait_until(pilot, lambda: listed.value is Select.NULL, what="the choice cleared")
        await pilot.pause()
        assert path.value == str(out)
        path.focus()
        await pilot.press("enter")
        await wait_until(pilot, lambda: app.sweep.active and app.sweep.done > first + 5, what="the resumed sweep")
        assert app.sweep.out == out and app.sweep.resumed_points == first
        # the plot shows the whole session, the status says what was there before
        await wait_until(pilot, lambda: f"({first} recorded before the resume)" in status_text(app), what="the status")
        assert app.sweep.traces[1].count >= app.sweep.done > first
        await pilot.press("a")
        await wait_until(pilot, lambda: app.sweep.status == "aborted", what="the second abort")
        s = read_session(out)
        assert s.attrs["session_id"] == session_id and s.attrs["outcome"] == "aborted"
        # every point once, in plan order, across both runs
        assert list(s.points["index"]) == list(range(app.sweep.done))
        assert np.all(np.isfinite(s.points["error_um"]))
        st = app.rig.axes[1].status()
        assert not st.moving and not st.enabled


def test_r_finishes_a_chosen_session_file_and_says_why_it_refuses_others(cfg, size, connected, wait_until, notes,
                                                                          tmp_path, recorded_session, six_leg_session):
    path, plan = aborted_session(tmp_path / "aborted.h5")
    asyncio.run(_resume_a_file(cfg, size, connected, wait_until, notes, path, plan, recorded_session, six_leg_session))


async def _resume_a_file(cfg, size, connected, wait_until, notes, path, plan, recorded_session, six_leg_session):
    app = StationApp(cfg, time_scale=0.02, hide_volatile=True)  # as above: a sweep to refuse r during
    async with app.run_test(size=size) as pilot:
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep page")
        await connected(pilot)

        async def resume(file) -> None:
            app.clear_notifications()
            dialog = await open_resume(pilot, wait_until)
            dialog.query_one("#resume-path", Input).value = str(file)
            await pilot.click("#resume-yes")
            await wait_until(pilot, lambda: not isinstance(app.screen, ResumeScreen), what="the dialog to close")

        # a complete session, one without a sweep plan, a missing file: refused, nothing runs
        await resume(recorded_session)
        await wait_until(pilot, lambda: any("already complete" in n and "nothing to resume" in n for n in notes(app)),
                         what="the refusal of a complete session")
        await resume(six_leg_session)
        await wait_until(pilot, lambda: any("cannot resume" in n and "six-legs.h5" in n for n in notes(app)),
                         what="the refusal of a session without a readable plan")
        await resume(path.with_name("missing.h5"))
        await wait_until(pilot, lambda: any("missing.h5: no such file" in n for n in notes(app)), what="the missing file")
        assert app.sweep.status == "idle"
        # Esc cancels
        await open_resume(pilot, wait_until)
        await pilot.press("escape")
        await wait_until(pilot, lambda: not isinstance(app.screen, ResumeScreen), what="the dialog to close")
        assert app.sweep.status == "idle"

        # the aborted file is finished: the same plan, appended
        await resume(path)
        await wait_until(pilot, lambda: app.sweep.status == "completed", what="the resumed sweep to complete")
        assert app.sweep.out == path and app.sweep.resumed_points == 4
        assert app.sweep.done == app.sweep.total == plan.total_points
        s = read_session(path)
        assert s.attrs["outcome"] == "completed"
        assert sorted(s.points["index"]) == list(range(plan.total_points))
        assert set(s.points["leg"]) == {2}
        assert app.last_session == path

        # r while a sweep runs is refused at once, without the dialog
        await start_paper_sweep(pilot, "3")
        await wait_until(pilot, lambda: app.sweep.active and app.sweep.done >= 1, what="a new sweep")
        app.clear_notifications()
        await pilot.press("r")
        await wait_until(pilot, lambda: any("A sweep is running: abort it first" in n for n in notes(app)),
                         what="the refusal while running")
        assert not isinstance(app.screen, ResumeScreen)
        await pilot.press("a")
        await wait_until(pilot, lambda: not app.sweep.active, what="the abort")
