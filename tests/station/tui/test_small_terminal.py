"""The UI in an 80x24 terminal (a bench laptop, an SSH session): the tab bar names all seven
pages, every page's controls are on screen (not cut, not scrolled away, not covered), and each
page's main action works by its key and by its button. Simulated rig (real Modbus TCP + serial
pty) where a page needs one. The same sizes are in the snapshots (snapshots/test_snapshots.py).
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from rich.text import Text
from textual.widgets import Button, Input, Static

from station.tui.app import StationApp
from station.tui.screens.common import PAGES, ConfirmScreen, nav_bar

pytestmark = pytest.mark.timeout(300)

SMALL = (80, 24)
REPO = Path(__file__).resolve().parents[3]
FAULTS = REPO / "recordings" / "fault-beam-break.h5"

# Per page: its key, and the controls that must be on show at 80x24 (its main action first).
CONTROLS = {
    "rig": ("f1", ["#drives", "#move-target", "#move-speed", "#move", "#jog-minus", "#jog-step", "#jog-plus", "#stop"]),
    "sweep": ("f2", ["#legs", "#plan", "#cycles", "#dwell", "#start", "#pause", "#abort", "#sweep-plot"]),
    "results": ("f3", ["#session-path", "#session-open", "#method", "#fit", "#save-model", "#write-report",
                       "#export-csv", "#results-table"]),
    "compensation": ("f4", ["#comp-step", "#comp-make", "#comp-read", "#comp-save", "#comp-push", "#comp-push-all",
                            "#comp-verify", "#comp-rollback", "#comp-table"]),
    "replay": ("f5", ["#session-path", "#session-open", "#replay-speed", "#replay-run", "#replay-results",
                      "#replay-diagnose", "#replay-faults"]),
    "diagnosis": ("f6", ["#session-path", "#session-open", "#twin", "#twin-spec", "#diag-run", "#diag-table"]),
    "platform": ("f7", ["#plat-comp", "#plat-recording", "#plat-poses", "#plat-seed", "#plat-run", "#plat-write",
                        "#plat-table"]),
}


def assert_on_show(app, selector: str, screen=None):
    """The widget `selector` of the screen on show (or `screen`), whole on the screen: not cut by
    the terminal or by its container, not scrolled away, and nothing (a toast, a dialog) over it."""
    screen = screen or app.screen
    widget = screen.query_one(selector)
    geometry = screen.find_widget(widget)
    region = geometry.region
    assert region.area > 0, f"{selector} has no room on screen"
    assert screen.region.contains_region(region), f"{selector} at {region} is cut by the {screen.region.size} terminal"
    assert geometry.visible_region == region, f"{selector} at {region} is cut by its container to {geometry.visible_region}"
    under, _ = screen.get_widget_at(region.x + region.width // 2, region.y + region.height // 2)
    assert under is widget or widget in under.ancestors, f"{selector} is covered by {under!r}"
    return widget


async def show_page(pilot, mode: str, wait_until) -> None:
    """Show the page `mode` and let it settle: its controls laid out and its footer recomposed
    for its keys (a page on show is laid out a refresh or two later; under load one pause was not
    that). If it never settles, the callers' checks say what is wrong with it."""
    app = pilot.app
    key, selectors = CONTROLS[mode]
    await pilot.press(key)
    await wait_until(pilot, lambda: app.screen.MODE == mode, what=f"the {mode} page")
    app.clear_notifications()

    def settled() -> bool:
        screen = app.screen
        shown = {b.binding.action for b in screen.active_bindings.values() if b.binding.show}
        keys = list(screen.query("StationFooter FooterKey"))
        return ({k.action for k in keys} >= shown and all(k.region.width > 0 for k in keys)
                and all(w.region.area > 0 for sel in selectors for w in screen.query(sel)))

    try:
        await wait_until(pilot, settled, 10, f"the {mode} page laid out")
    except AssertionError:
        pass  # the checks that follow name the control that has no room, or the key missing
    await pilot.pause()


async def click(pilot, selector: str):
    """Click the button `selector` after checking it is on show (Pilot clicks where it is)."""
    assert_on_show(pilot.app, selector)
    await pilot.click(selector)
    await pilot.pause()


def make_app(cfg, **kwargs) -> StationApp:
    kwargs.setdefault("autoconnect", False)
    return StationApp(cfg, **kwargs)


# -- the frame ---------------------------------------------------------------------------------------

def test_the_tab_bar_names_all_seven_pages_in_80_columns_and_wider():
    for width in (80, 100, 130):
        for mode, _, _ in PAGES:
            bar = Text.from_markup(nav_bar(mode, width)).plain
            assert Text.from_markup(nav_bar(mode, width)).cell_len <= width
            for _, key, _ in PAGES:
                assert key in bar, f"{key} missing from the tab bar at {width} columns: {bar!r}"
            assert "Platf" in bar and "Rig" in bar
    # wide: as before, every title in full
    assert "F4 Compensation" in Text.from_markup(nav_bar("rig", 120)).plain
    # so narrow only the current page keeps a title, but every key is there
    tiny = Text.from_markup(nav_bar("results", 40)).plain
    assert all(key in tiny for _, key, _ in PAGES) and "Results" in tiny


@pytest.mark.parametrize("size", [SMALL, (100, 30), (120, 40), (130, 40)], ids=lambda s: f"{s[0]}x{s[1]}")
def test_every_page_has_its_controls_the_tab_bar_and_the_help_key_on_show(cfg, wait_until, size):
    asyncio.run(_controls_on_show(cfg, wait_until, size))


async def _controls_on_show(cfg, wait_until, size=SMALL):
    app = make_app(cfg)
    async with app.run_test(size=size) as pilot:
        for mode, (_, selectors) in CONTROLS.items():
            await show_page(pilot, mode, wait_until)
            screen = app.screen
            assert screen.has_class("-narrow") == (size[0] < 120) and screen.has_class("-short") == (size[1] < 32)
            bar = assert_on_show(app, ".nav-bar")
            text = Text.from_markup(str(bar.content)).plain
            assert all(key in text for _, key, _ in PAGES), text
            assert bar.region.width == size[0]
            assert_on_show(app, "StationFooter FooterKey" + (".-help-key" if size[0] < 120 else ""))
            for key in screen.query("StationFooter FooterKey"):  # every key whole: its key and its words
                drawn = f"{key.key_display or key.key} {key.description}".strip()
                assert key.region.right <= size[0] and key.content_region.width >= len(drawn), (mode, drawn, key.region)
            for selector in selectors:
                assert_on_show(app, selector)
            if mode == "sweep":  # the form opens at its top
                assert screen.query_one("#sweep-form").scroll_y == 0
        # the help opens over any page, fits and scrolls
        await pilot.press("question_mark")
        await wait_until(pilot, lambda: app.screen.query("#help-scroll"), what="the help")
        await pilot.pause()
        scroll = assert_on_show(app, "#help-scroll")
        assert_on_show(app, "#help-close")
        assert scroll.max_scroll_y > 0
        await pilot.press("end")
        await wait_until(pilot, lambda: scroll.scroll_y == scroll.max_scroll_y, what="the help's end")
        await pilot.press("escape")


# -- each page's main action, by its key and by its button ---------------------------------------------

def test_rig_page_enable_move_jog_and_stop_at_80x24(cfg, connected, wait_until):
    asyncio.run(_rig(cfg, connected, wait_until))


async def _rig(cfg, connected, wait_until):
    app = make_app(cfg, autoconnect=True, time_scale=0.0, poll_interval_s=0.1)
    async with app.run_test(size=SMALL) as pilot:
        await connected(pilot)

        def position() -> float:
            return app.rig.axes[1].status().position_mm

        await pilot.press("e")
        await wait_until(pilot, lambda: app.rig.axes[1].status().enabled, what="leg 1 enabled (e)")
        app.screen.query_one("#move-target", Input).value = "12"
        await click(pilot, "#move")
        await wait_until(pilot, lambda: not app.rig_motion and position() == pytest.approx(12.0, abs=1e-6),
                         what="the move to 12 mm (Move button)")
        app.screen.query_one("#move-target", Input).value = "-4"
        app.screen.query_one("#drives").focus()
        await pilot.press("m")
        await wait_until(pilot, lambda: not app.rig_motion and position() == pytest.approx(-4.0, abs=1e-6),
                         what="the move to -4 mm (m)")
        await click(pilot, "#jog-plus")
        await wait_until(pilot, lambda: not app.rig_motion and position() == pytest.approx(-3.0, abs=1e-6),
                         what="the jog +1 mm (+ button)")
        app.screen.query_one("#drives").focus()
        await pilot.press("minus")
        await wait_until(pilot, lambda: not app.rig_motion and position() == pytest.approx(-4.0, abs=1e-6),
                         what="the jog -1 mm (-)")
        await click(pilot, "#stop")
        await wait_until(pilot, lambda: str(app.rig.axes[1].status().state) == "quick_stop_active",
                         what="the stop (Stop button)")


def test_sweep_page_start_pause_resume_abort_at_80x24(cfg, connected, wait_until):
    asyncio.run(_sweep(cfg, connected, wait_until))


async def _sweep(cfg, connected, wait_until):
    # the paper plan at time scale 0.02: minutes, time to pause and abort it (as tests.tooling.start_paper_sweep)
    app = make_app(cfg, autoconnect=True, time_scale=0.02, hide_volatile=True)
    async with app.run_test(size=SMALL) as pilot:
        await connected(pilot)
        await show_page(pilot, "sweep", wait_until)
        app.screen.query_one("#plan").value = "paper"
        await pilot.pause()
        app.screen.query_one("#legs", Input).value = "2"
        await pilot.pause()
        await click(pilot, "#start")
        await wait_until(pilot, lambda: app.sweep.status == "running", what="the sweep (Start button)")
        await pilot.press("p")
        await wait_until(pilot, lambda: app.sweep.status == "paused", what="the pause (p)")
        await wait_until(pilot, lambda: str(app.screen.query_one("#pause", Button).label) == "Resume (p)",
                         what="the Resume button")
        await click(pilot, "#pause")
        await wait_until(pilot, lambda: app.sweep.status == "running", what="the resume (Resume button)")
        await click(pilot, "#abort")
        await wait_until(pilot, lambda: app.sweep.status == "aborted", 30, "the abort (Abort button)")
        await wait_until(pilot, lambda: app.screen.query_one("#start", Button).disabled is False, what="Start again")
        app.screen.query_one("#start", Button).focus()
        await pilot.press("s")
        await wait_until(pilot, lambda: app.sweep.status == "running", what="the sweep (s)")
        await pilot.press("a")
        await wait_until(pilot, lambda: app.sweep.status == "aborted", 30, "the abort (a)")


def test_results_and_compensation_fit_make_push_verify_rollback_at_80x24(cfg, connected, wait_until,
                                                                           recorded_session):
    asyncio.run(_results_and_compensation(cfg, connected, wait_until, recorded_session))


async def _results_and_compensation(cfg, connected, wait_until, session):
    app = make_app(cfg, autoconnect=True, time_scale=0.0)
    async with app.run_test(size=SMALL) as pilot:
        await connected(pilot)
        # Results: open (button), fit (f), fit again (button)
        await show_page(pilot, "results", wait_until)
        app.screen.query_one("#session-path", Input).value = str(session)
        await click(pilot, "#session-open")
        await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit (Open)")
        first = app.analysis
        app.screen.query_one("#results-table").focus()
        await pilot.press("f")
        await wait_until(pilot, lambda: app.analysis is not first, 60, "the fit (f)")
        second = app.analysis
        await click(pilot, "#fit")
        await wait_until(pilot, lambda: app.analysis is not second, 60, "the fit (Fit button)")
        # the ISO 230-2 columns beside the leg, on show
        table = app.screen.query_one("#results-table")
        labels = [str(c.label) for c in table.columns.values()]
        assert labels[:6] == ["Leg", "A", "E", "M", "B", "R"]
        # the table shows its legs and the plots keep 8 rows or more (the page scrolls to them)
        assert table.region.height >= 4
        for plot in ("#model-plot", "#residual-plot"):
            assert app.screen.query_one(plot).region.height >= 8, plot

        # Compensation: the table (made on showing the page; t, then the button), push (u, then
        # the button: the confirmation's buttons on show), verify (v), rollback (button)
        await show_page(pilot, "compensation", wait_until)
        await wait_until(pilot, lambda: app.screen.table is not None, what="the table")
        comp = app.screen
        made = comp.table
        comp.query_one("#comp-table").focus()
        await pilot.press("t")
        await wait_until(pilot, lambda: comp.table is not made, what="the table (t)")
        made = comp.table
        await click(pilot, "#comp-make")
        await wait_until(pilot, lambda: comp.table is not made, what="the table (Make button)")

        await pilot.press("u")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the push confirmation (u)")
        await pilot.pause()
        for selector in ("#confirm-yes", "#confirm-no", "#confirm-scroll"):
            assert_on_show(app, selector)
        await pilot.press("n")
        await wait_until(pilot, lambda: app.screen is comp, what="the confirmation to close")
        app.clear_notifications()
        await pilot.pause()
        await click(pilot, "#comp-push")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the push confirmation (button)")
        await pilot.pause()
        await click(pilot, "#confirm-yes")
        await wait_until(pilot, lambda: app.screen is comp and app.rig.axes[1].status().active_bank == 1, 30,
                         "the push")

        await show_page(pilot, "compensation", wait_until)
        comp.query_one("#comp-table").focus()
        await pilot.press("v")
        await wait_until(pilot, lambda: app.sweep.label.startswith("verification"), what="the verification (v)")
        await wait_until(pilot, lambda: not app.sweep.active, 120, "the verification to end")
        await wait_until(pilot, lambda: comp.verify_text, 30, "the verification report")
        # its verdict on show at the top of the page, without scrolling (the report runs below the fold)
        await show_page(pilot, "compensation", wait_until)
        verdict = assert_on_show(app, "#comp-verdict")
        assert comp.query_one("#comp-body").scroll_y == 0
        assert "leg 1 verification: " in str(verdict.render()) and "ratio" in str(verdict.render())

        await show_page(pilot, "compensation", wait_until)
        await click(pilot, "#comp-rollback")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen) and app.screen.query("#confirm-question"), what="the rollback confirmation")
        await pilot.pause()
        assert_on_show(app, "#confirm-yes")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.screen is comp and app.rig.axes[1].status().active_bank == 0, 30,
                         "the rollback")


def test_replay_diagnosis_and_platform_at_80x24(cfg, wait_until, six_leg_session):
    asyncio.run(_replay_diagnosis_platform(cfg, wait_until, six_leg_session))


async def _replay_diagnosis_platform(cfg, wait_until, session):
    app = make_app(cfg, time_scale=0.0)
    async with app.run_test(size=SMALL) as pilot:
        # Replay: open the recording with the beam break, replay it (button), again (r)
        await show_page(pilot, "replay", wait_until)
        replay = app.screen
        replay.query_one("#session-path", Input).value = str(FAULTS)
        await click(pilot, "#session-open")
        await wait_until(pilot, lambda: replay.session is not None, 30, "the recording")
        await click(pilot, "#replay-run")
        await wait_until(pilot, lambda: app.sweep.label.startswith("replay"), what="the replay (Replay button)")
        await wait_until(pilot, lambda: not app.sweep.active, 90, "the replay to end")
        first = app.sweep
        await show_page(pilot, "replay", wait_until)
        replay.query_one("#replay-faults").focus()
        await pilot.press("r")
        await wait_until(pilot, lambda: app.sweep is not first and app.sweep.label.startswith("replay"),
                         what="the replay (r)")
        await wait_until(pilot, lambda: not app.sweep.active, 90, "the replay to end")

        # Diagnosis: d, then the button
        await show_page(pilot, "diagnosis", wait_until)
        diag = app.screen
        diag.query_one("#session-path", Input).value = str(session)
        diag.query_one("#diag-table").focus()
        await pilot.press("d")
        await wait_until(pilot, lambda: diag.report is not None and not diag.running, 90, "the diagnosis (d)")
        report = diag.report
        await click(pilot, "#diag-run")
        await wait_until(pilot, lambda: diag.report is not report and not diag.running, 90,
                         "the diagnosis (Diagnose button)")
        assert diag.query_one("#diag-table").columns  # the p column before the parameters
        labels = [str(c.label) for c in diag.query_one("#diag-table").columns.values()]
        assert labels.index("p") < labels.index("Parameters")

        # Platform: the session fitted on Results; p, then the button
        await show_page(pilot, "results", wait_until)
        app.screen.query_one("#session-path", Input).value = str(session)
        await click(pilot, "#session-open")
        await wait_until(pilot, lambda: app.analysis is not None and app.analysis.path == session, 60, "the fit")
        await show_page(pilot, "platform", wait_until)
        plat = app.screen
        await pilot.press("p")
        await wait_until(pilot, lambda: plat.platform_run is not None and not plat.running, 90, "the run (p)")
        run = plat.platform_run
        await click(pilot, "#plat-run")
        await wait_until(pilot, lambda: plat.platform_run is not run and not plat.running, 90, "the run (Run button)")
        # Table 2: every component on show (the short labels)
        assert_on_show(app, "#plat-table")
        labels = [str(c.label) for c in plat.query_one("#plat-table").columns.values()]
        assert len(labels) == 7 and labels[0] == "Measure"
        status = str(plat.query_one("#plat-status", Static).render())
        assert "2000 of 2000 poses" in status or "poses used" in status


def test_a_resized_terminal_lays_the_pages_out_again(cfg, wait_until, recorded_session):
    asyncio.run(_resized(cfg, wait_until, recorded_session))


async def _resized(cfg, wait_until, session):
    app = make_app(cfg)
    async with app.run_test(size=(120, 40)) as pilot:
        await show_page(pilot, "results", wait_until)
        app.screen.query_one("#session-path", Input).value = str(session)
        await click(pilot, "#session-open")
        await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit")
        results = app.screen

        def labels(screen, selector) -> list[str]:
            return [str(c.label) for c in screen.query_one(selector).columns.values()]

        def bar(screen) -> str:
            return Text.from_markup(str(screen.query_one(".nav-bar").content)).plain

        assert labels(results, "#results-table")[:3] == ["Leg", "Points", "Cycles"]
        assert "F4 Compensation" in bar(results) and not results.has_class("-narrow")
        await pilot.resize_terminal(*SMALL)
        await wait_until(pilot, lambda: results.has_class("-narrow") and results.has_class("-short"), what="-narrow")
        await wait_until(pilot, lambda: labels(results, "#results-table")[:6] == ["Leg", "A", "E", "M", "B", "R"],
                         what="the narrow columns")
        assert results.query_one("#results-table").row_count == 2  # the rows again
        assert len(bar(results)) <= SMALL[0] and "F7" in bar(results)
        # a page not on show when the terminal changed is laid out when shown
        await show_page(pilot, "rig", wait_until)
        assert labels(app.screen, "#drives")[2] == "Pos. mm" and app.screen.has_class("-short")
        await pilot.resize_terminal(120, 40)
        await wait_until(pilot, lambda: labels(app.screen, "#drives")[2] == "Position mm", what="the wide Rig columns")
        await show_page(pilot, "results", wait_until)
        await wait_until(pilot, lambda: labels(results, "#results-table")[:3] == ["Leg", "Points", "Cycles"],
                         what="the wide columns")
        assert not results.has_class("-narrow") and "F4 Compensation" in bar(results)
