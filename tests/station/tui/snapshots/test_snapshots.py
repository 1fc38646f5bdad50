"""Snapshot tests of the main screens (pytest-textual-snapshot).

Nothing that varies is in view: the apps are built with `hide_volatile=True` (no clocks, ETAs,
device addresses or file paths) and `autoconnect=False` (no live readings). Update the stored
SVGs with `pytest tests/station/tui/snapshots --snapshot-update` after an intended change, and
look at them before committing.
"""

from __future__ import annotations

from station.config import StationConfig
from station.tui.app import StationApp

SIZE = (120, 40)


def make_app(tmp_path) -> StationApp:
    cfg = StationConfig(operator="test")
    cfg.recordings_dir = str(tmp_path / "runs")  # empty: no session names in the pickers
    return StationApp(cfg, autoconnect=False, hide_volatile=True)


def test_rig_screen(snap_compare, tmp_path):
    assert snap_compare(make_app(tmp_path), terminal_size=SIZE)


def test_sweep_screen_before_a_run(snap_compare, tmp_path):
    assert snap_compare(make_app(tmp_path), press=["f2"], terminal_size=SIZE)


def test_sweep_screen_paper_plan(snap_compare, tmp_path):
    async def choose_paper(pilot):
        await pilot.press("f2")
        await pilot.pause()
        pilot.app.screen.query_one("#plan").value = "paper"
        await pilot.pause()

    assert snap_compare(make_app(tmp_path), run_before=choose_paper, terminal_size=SIZE)


def test_results_screen_without_a_session(snap_compare, tmp_path):
    assert snap_compare(make_app(tmp_path), press=["f3"], terminal_size=SIZE)


def test_compensation_screen_without_a_model(snap_compare, tmp_path):
    assert snap_compare(make_app(tmp_path), press=["f4"], terminal_size=SIZE)


def test_platform_screen_after_a_run(snap_compare, tmp_path, six_leg_session, wait_until):
    """F7 after `p` on a synthetic six-leg session fitted on Results: Table 2, legs against pose
    for both measurements, the histograms of x (2000 poses, seed 0)."""

    async def fit_and_run(pilot):
        app = pilot.app
        await pilot.press("f3")
        await wait_until(pilot, lambda: app.screen.query("#session-path"), what="the session picker")
        app.screen.query_one("#session-path").value = str(six_leg_session)
        await pilot.click("#session-open")
        await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit")
        await pilot.press("f7")
        await wait_until(pilot, lambda: app.screen.MODE == "platform", what="the Platform page")
        await pilot.press("p")
        await wait_until(pilot, lambda: app.screen.platform_run is not None, 60, "the platform experiment")
        app.clear_notifications()
        await pilot.pause()

    assert snap_compare(make_app(tmp_path), run_before=fit_and_run, terminal_size=SIZE)
