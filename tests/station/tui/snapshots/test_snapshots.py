"""Snapshot tests of the main screens (pytest-textual-snapshot).

Nothing that varies is in view: the apps are built with `hide_volatile=True` (no clocks, ETAs,
device addresses or file paths) and `autoconnect=False` (no live readings). Update the stored
SVGs with `pytest tests/station/tui/snapshots --snapshot-update` after an intended change, and
look at them before committing.
"""

from __future__ import annotations

from pathlib import Path

from station.services.config import StationConfig
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


# -- an 80x24 terminal (a bench laptop, an SSH session): every page, its controls on show ----------

SMALL = (80, 24)
REPO = Path(__file__).resolve().parents[4]


async def _fit_on_results(pilot, wait_until, session) -> None:
    """Open `session` on Results and fit it (default model); the path typed is cleared after
    (it varies from run to run)."""
    app = pilot.app
    await pilot.press("f3")
    await wait_until(pilot, lambda: app.screen.query("#session-path"), what="the session picker")
    app.screen.query_one("#session-path").value = str(session)
    await pilot.click("#session-open")
    await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit")
    app.screen.query_one("#session-path").value = ""


async def _settle(pilot) -> None:
    pilot.app.clear_notifications()
    await pilot.pause()


def test_rig_screen_80x24(snap_compare, tmp_path):
    """All seven pages in the tab bar; the move and the jog on two rows; the help key in the footer."""
    assert snap_compare(make_app(tmp_path), terminal_size=SMALL)


def test_sweep_screen_80x24(snap_compare, tmp_path):
    """Opens at the top: Legs, Plan, ..., Start, Pause and Abort all on show."""
    assert snap_compare(make_app(tmp_path), press=["f2"], terminal_size=SMALL)


def test_results_screen_80x24_after_a_fit(snap_compare, tmp_path, six_leg_session, wait_until):
    """The controls on one row; the ISO 230-2 columns A..R beside the leg, then the held-out figures."""

    async def fit(pilot):
        await _fit_on_results(pilot, wait_until, six_leg_session)
        await _settle(pilot)

    assert snap_compare(make_app(tmp_path), run_before=fit, terminal_size=SMALL)


def test_compensation_screen_80x24_with_a_table(snap_compare, tmp_path, six_leg_session, wait_until):
    """Make / Read / CSV on one row, Push / All / Verify / Rollback on the next; the table's ranges
    beside the leg."""

    async def fit_and_make(pilot):
        app = pilot.app
        await _fit_on_results(pilot, wait_until, six_leg_session)
        await pilot.press("f4")
        await wait_until(pilot, lambda: app.screen.MODE == "compensation" and app.screen.table is not None,
                         what="the table")
        await _settle(pilot)

    assert snap_compare(make_app(tmp_path), run_before=fit_and_make, terminal_size=SMALL)


def test_replay_screen_80x24_with_faults(snap_compare, tmp_path, wait_until):
    """A recording with a beam break: the faults' kind, attempt and message beside the leg and run."""

    async def open_faults(pilot):
        app = pilot.app
        await pilot.press("f5")
        await wait_until(pilot, lambda: app.screen.MODE == "replay", what="the Replay page")
        app.screen.query_one("#session-path").value = str(REPO / "recordings" / "fault-beam-break.h5")
        await pilot.click("#session-open")
        await wait_until(pilot, lambda: app.screen.session is not None, 30, "the session")
        app.screen.query_one("#session-path").value = ""
        await _settle(pilot)

    assert snap_compare(make_app(tmp_path), run_before=open_faults, terminal_size=SMALL)


def test_diagnosis_screen_80x24_after_a_run(snap_compare, tmp_path, six_leg_session, wait_until):
    """The findings with their p values (the parameters last), the plot and the text report."""

    async def diagnose(pilot):
        app = pilot.app
        await pilot.press("f6")
        await wait_until(pilot, lambda: app.screen.MODE == "diagnosis", what="the Diagnosis page")
        app.screen.query_one("#session-path").value = str(six_leg_session)
        await pilot.click("#diag-run")
        await wait_until(pilot, lambda: app.screen.report is not None, 90, "the diagnosis")
        app.screen.query_one("#session-path").value = ""
        await _settle(pilot)

    assert snap_compare(make_app(tmp_path), run_before=diagnose, terminal_size=SMALL)


def test_platform_screen_80x24_after_a_run(snap_compare, tmp_path, six_leg_session, wait_until):
    """Table 2 with short labels, all six components on show; the legs table below (the
    histograms a scroll away)."""

    async def fit_and_run(pilot):
        app = pilot.app
        await _fit_on_results(pilot, wait_until, six_leg_session)
        await pilot.press("f7")
        await wait_until(pilot, lambda: app.screen.MODE == "platform", what="the Platform page")
        await pilot.press("p")
        await wait_until(pilot, lambda: app.screen.platform_run is not None, 60, "the platform experiment")
        await _settle(pilot)

    assert snap_compare(make_app(tmp_path), run_before=fit_and_run, terminal_size=SMALL)


def test_help_80x24(snap_compare, tmp_path):
    """The key help fits the terminal and scrolls; its key lines break between keys."""
    assert snap_compare(make_app(tmp_path), press=["question_mark"], terminal_size=SMALL)
