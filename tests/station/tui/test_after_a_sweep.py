"""The pages after a sweep (issue 22, item 8): F3 and F5 open the session just recorded (not "no
session open" with its path filled in); Open has a key (ctrl+o, also from the path field); F7
says "press p" only for what p accepts (a one-leg model: what is missing); what the UI makes of
a sample session (recordings/, tracked by git) is written under the runs folder, never there.
Simulated rig (real Modbus TCP + serial pty)."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from textual.widgets import Input, Static

from station.tui.app import StationApp

pytestmark = pytest.mark.timeout(300)

REPO = Path(__file__).resolve().parents[3]
SAMPLE = REPO / "recordings" / "fault-beam-break.h5"


def text_of(app, selector: str) -> str:
    return str(app.screen.query_one(selector, Static).render())


def test_after_a_sweep_f3_f5_open_it_and_f7_says_what_p_needs(cfg, size, connected, wait_until, recorded_session):
    asyncio.run(_after_a_sweep(cfg, size, connected, wait_until, recorded_session))


async def _after_a_sweep(cfg, size, connected, wait_until, recorded_session):
    app = StationApp(cfg, time_scale=0.0, poll_interval_s=0.5)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep page")
        for wid, value in (("step", "20"), ("cycles", "3"), ("dwell", "0")):
            app.screen.query_one(f"#{wid}", Input).value = value
        await pilot.pause()
        await pilot.click("#start")
        await wait_until(pilot, lambda: app.sweep.status == "completed", 60, "the sweep")
        out = app.sweep.out

        await pilot.press("f3")  # Results: the sweep's session, opened and fitted
        await wait_until(pilot, lambda: app.analysis is not None and app.analysis.path == out, 60,
                         f"the session on F3 ({text_of(app, '#results-status')})")
        assert "no session open" not in text_of(app, "#results-status")

        await pilot.press("f5")  # Replay: the same session, read
        await wait_until(pilot, lambda: out.name in text_of(app, "#replay-info"), 30, "the session on F5")

        await pilot.press("f7")  # a one-leg model: no "press p", but what is missing
        await wait_until(pilot, lambda: app.screen.MODE == "platform", what="the Platform page")
        status = text_of(app, "#plat-status")
        assert "press p" not in status and "no [2, 3, 4, 5, 6]" in status and "needs all six legs" in status

        # Open by its key, from the path field: another session on Results
        await pilot.press("f3")
        await wait_until(pilot, lambda: app.screen.MODE == "results", what="the Results page")
        field = app.screen.query_one("#session-path", Input)
        field.value = str(recorded_session)
        field.focus()
        await pilot.press("ctrl+o")
        await wait_until(pilot, lambda: app.analysis.path == recorded_session, 60, "the session opened by ctrl+o")


def test_what_the_ui_makes_of_a_sample_session_goes_under_runs(cfg, size, wait_until, notes):
    if not SAMPLE.exists():
        pytest.skip(f"{SAMPLE} is not in this checkout")
    asyncio.run(_sample_outputs(cfg, size, wait_until, notes))


async def _sample_outputs(cfg, size, wait_until, notes):
    before = sorted(p.name for p in SAMPLE.parent.iterdir())
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=size) as pilot:
        await pilot.press("f3")
        await wait_until(pilot, lambda: app.screen.MODE == "results", what="the Results page")
        app.screen.query_one("#session-path", Input).value = str(SAMPLE)
        await pilot.click("#session-open")
        await wait_until(pilot, lambda: app.analysis is not None and app.analysis.path == SAMPLE, 60, "the fit")
        await pilot.press("w")
        await wait_until(pilot, lambda: app.analysis.model_path is not None, what="the model saved")
        model = app.analysis.model_path
        assert model.parent == Path(cfg.recordings_dir) and model.exists()
    assert sorted(p.name for p in SAMPLE.parent.iterdir()) == before, "nothing written into recordings/"
