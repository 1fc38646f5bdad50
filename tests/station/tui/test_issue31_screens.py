"""The terminal UI's reproductions of issue 31 ("Why"), run again through Pilot:

- Rig page (F1): `e`, Tab to the target field, `1,5`, Enter moved leg 1 to +15 mm (the field
  dropped the comma). Now the field holds `1,5`, refuses it next to itself ("write 1.5 with a
  decimal point") and nothing reaches the drive; `1.5` is shown with the leg's soft limits before
  Enter moves it there.
- Typing "abc" outside a field pressed `c` and reset the simulated rig. Now a rig key acts only
  when pressed on its own (StationScreen.RIG_KEYS), and reconnecting a connected rig asks first.
- 80x24: every footer key of every page whole and apart from the next (read from the rendered
  screen), `t` in the Results footer, the Results range column whole, the Serials placeholder
  whole (at 120x40 too), the quit dialog not covered by notifications, the live plot's x axis
  spanning the leg's targets from the first point. (The Compensation verdict on show without
  scrolling: test_small_terminal.py, after its verification at 80x24.)
"""

from __future__ import annotations

import asyncio
import time

import pytest
from textual.widgets import DataTable, Input, Static

from station.tui.app import StationApp
from station.tui.screens.common import PAGES, ConfirmScreen, StationFooter
from tests.station.tui.steps import type_keys

pytestmark = pytest.mark.timeout(300)

SMALL = (80, 24)
PAGE_KEYS = [(mode, key.lower()) for mode, key, _ in PAGES]


def screen_lines(app) -> list[str]:
    """The text of the terminal as the app has drawn it, one string per row."""
    update = app.screen._compositor.render_full_update(simplify=True)
    return ["".join(segment.text for strip in row for segment in strip) for row in update.strips]


def text_of(widget) -> str:
    return str(widget.render())


def set_points(app, leg: int = 1) -> int:
    return app.rig.sim.drive_server.set_points(leg)


# -- the comma -------------------------------------------------------------------------------------------

def test_1_comma_5_in_the_target_field_is_refused_and_nothing_moves(cfg, connected, wait_until, notes):
    asyncio.run(_comma(cfg, connected, wait_until, notes))


async def _comma(cfg, connected, wait_until, notes):
    app = StationApp(cfg, time_scale=0.0, poll_interval_s=0.2)
    async with app.run_test(size=SMALL) as pilot:
        await connected(pilot)
        screen = app.screen
        await wait_until(pilot, lambda: "soft limits -95.000 .. +95.000 mm" in text_of(screen.query_one("#move-status")),
                         what="the soft limits")
        await pilot.press("e")
        await wait_until(pilot, lambda: app.rig.axes[1].status().enabled, what="leg 1 enabled (e)")
        target = screen.query_one("#move-target", Input)
        for _ in range(6):  # Tab to the target field
            if app.focused is target:
                break
            was = app.focused
            await pilot.press("tab")
            # each Tab handled before the next is counted (under load Pilot.press returns before)
            await wait_until(pilot, lambda: app.focused is not was, what="Tab to move the focus")
        assert app.focused is target
        before = set_points(app)
        await pilot.press("1", "comma", "5")
        # (Pilot.press returns once the app looks idle, which under load can be before the keys are handled)
        await wait_until(pilot, lambda: target.value == "1,5", what="the field to keep every character typed")
        # the status follows the field's Changed message, handled after the value is set
        await wait_until(pilot, lambda: "'1,5'" in text_of(screen.query_one("#move-status", Static)),
                         what="the status to show 1,5")
        status = text_of(screen.query_one("#move-status", Static))
        assert "leg 1 target: '1,5': a comma is not a decimal separator here" in status
        assert "write 1.5 with a decimal point" in status
        assert target.has_class("-invalid")
        await pilot.press("enter")
        await wait_until(pilot, lambda: any("write 1.5 with a decimal point" in n and "nothing moved" in n
                                            for n in notes(app)), what="the refusal")
        await pilot.pause(0.3)
        assert set_points(app) == before, "a set-point reached the drive"
        assert not app.rig_motion
        assert app.rig.axes[1].status().position_mm == pytest.approx(0.0, abs=1e-9)
        # 1.5: shown with the leg's soft limits before it moves; Enter moves it there
        target.value = ""
        await pilot.press("1", "full_stop", "5")
        await wait_until(pilot, lambda: target.value == "1.5" and "+1.500 mm" in text_of(screen.query_one("#move-status")),
                         what="1.5 typed and shown")
        status = text_of(screen.query_one("#move-status", Static))
        assert "leg 1 → +1.500 mm at the default speed (soft limits -95.000 .. +95.000 mm): Enter or m moves it" in status
        assert set_points(app) == before and not target.has_class("-invalid")
        await pilot.press("enter")
        await wait_until(pilot, lambda: not app.rig_motion and "leg 1 at +1.5000 mm" in app.rig_motion_text,
                         what="the move to 1.5 mm")
        assert app.rig.axes[1].status().position_mm == pytest.approx(1.5, abs=1e-6)
        # beyond the soft limits: refused as typed, naming them
        target.value = ""
        await pilot.press("9", "6")
        await wait_until(pilot, lambda: target.value == "96" and "'96'" in text_of(screen.query_one("#move-status")),
                         what="96 typed and shown")
        status = text_of(screen.query_one("#move-status", Static))
        assert "leg 1 target: '96' is outside -95 .. 95 mm; give a position within leg 1's soft limits" in status


# -- keys act only where they are shown, on their own --------------------------------------------------------

def test_typing_outside_a_field_never_acts_on_the_rig(cfg, connected, wait_until, notes, rig_keys_act):
    asyncio.run(_stray(cfg, connected, wait_until, notes, rig_keys_act))


async def _stray(cfg, connected, wait_until, notes, rig_keys_act):
    app = StationApp(cfg, time_scale=0.0, poll_interval_s=0.2)
    async with app.run_test(size=SMALL) as pilot:
        await connected(pilot)
        rig = app.rig
        screen = app.screen
        screen.query_one("#drives", DataTable).focus()
        await pilot.pause(screen.STRAY_HOLD_S + 0.1)
        # "abc": a and b are no keys of the Rig page, so c comes in a run of typing: ignored
        typed = time.monotonic()
        await type_keys(pilot, "abc")  # a typist's burst
        # (the notice comes as c is handled, which on a busy machine is not at once)
        await wait_until(pilot, lambda: any("c (Connect) ignored: it came right after typing outside a field (ab)" in n
                                            for n in notes(app)), what="the notice that c was ignored")
        await pilot.pause(screen.ALONE_S + 0.2)  # c would have acted by now, had it been taken alone
        assert app.rig is rig and app.rig_state == "connected", "c reconnected (the simulated rig restarted)"
        assert not isinstance(app.screen, ConfirmScreen)
        # "hello": h (home) and e (enable) are keys of the page, but each is followed by another key
        await rig_keys_act(pilot, typed)
        before = set_points(app)
        typed = time.monotonic()
        await type_keys(pilot, "hello")  # a typist's burst
        await wait_until(pilot, lambda: any("h (Home (0 mm)) ignored: another key followed it at once" in n
                                            for n in notes(app)), what="the notice that h was ignored")
        await pilot.pause(screen.ALONE_S + 0.3)  # h or e would have acted by now
        assert set_points(app) == before and not app.rig.axes[1].status().enabled
        # "-25" typed where the focus is not a field: not a jog
        await rig_keys_act(pilot, typed)
        typed = time.monotonic()
        await type_keys(pilot, "-25")
        await pilot.pause(screen.ALONE_S + 0.3)
        assert set_points(app) == before and not app.rig_motion
        # e on its own enables; + + + jogs three times (the same key again acts each time)
        await rig_keys_act(pilot, typed)
        await pilot.press("e")
        await wait_until(pilot, lambda: app.rig.axes[1].status().enabled, what="leg 1 enabled (e on its own)")
        await pilot.press("plus")
        await wait_until(pilot, lambda: not app.rig_motion and "+1.0000 mm" in app.rig_motion_text, what="jog +1")
        # c on its own, connected: asks first; no keeps the rig
        await pilot.press("c")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="the reconnect question")
        # (the dialog is pushed before it is composed: wait for its question, not a fixed pause)
        await wait_until(pilot, lambda: app.screen.query("#confirm-question"), what="the question's text")
        assert "Reconnect to the rig?" in text_of(app.screen.query_one("#confirm-question"))
        await pilot.press("n")
        await wait_until(pilot, lambda: app.screen is screen, what="the question closed")
        assert app.rig is rig
        # Sweep page: "abcs" does not start a sweep
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep page")
        app.screen.query_one("#start").focus()
        await pilot.pause(app.screen.STRAY_HOLD_S + 0.1)
        await type_keys(pilot, "abcs")
        await pilot.pause(app.screen.ALONE_S + 0.3)
        assert app.sweep.status == "idle"


# -- 80x24 -------------------------------------------------------------------------------------------------

def test_every_footer_key_of_every_page_is_shown_whole_at_80x24(cfg, wait_until):
    asyncio.run(_footers(cfg, wait_until))


async def _footers(cfg, wait_until):
    app = StationApp(cfg, autoconnect=False)
    checked = []
    async with app.run_test(size=SMALL) as pilot:
        for mode, key in PAGE_KEYS:
            await pilot.press(key)
            await wait_until(pilot, lambda: app.screen.MODE == mode, what=f"the {mode} page")
            screen = app.screen
            footer = screen.query_one(StationFooter)

            def shown() -> set[str]:
                return {b.binding.action for b in screen.active_bindings.values() if b.binding.show}

            def drawn_whole() -> bool:
                keys = list(footer.query("FooterKey"))
                return ({k.action for k in keys} >= shown() and footer.region.height > 0
                        and all(k.region.width > 0 for k in keys)
                        and any(line.strip() for line in screen_lines(app)[footer.region.y:footer.region.bottom]))

            # every binding the page shows has its key in the footer (one key per action: + for plus/=),
            # drawn: the footer recomposes for the page's bindings and is laid out a refresh or two
            # after the page is on show (under load a pause was not enough: no keys yet, or blank rows)
            await wait_until(pilot, drawn_whole, 10, f"the {mode} page's footer to show its keys {sorted(shown())}")
            lines = screen_lines(app)[footer.region.y:footer.region.bottom]
            keys = list(footer.query("FooterKey"))
            assert {k.action for k in keys} >= shown(), (mode, sorted(shown() - {k.action for k in keys}))
            for k in keys:
                drawn = f"{k.key_display or k.key} {k.description}"
                row = next((line for line in lines if drawn in line), None)
                assert row is not None, f"{mode}: {drawn!r} is not whole in the footer {lines}"
                at = row.index(drawn)
                before, after = row[at - 1:at] or " ", row[at + len(drawn):at + len(drawn) + 1] or " "
                assert before == " " and after == " ", f"{mode}: {drawn!r} runs into its neighbour: {row!r}"
                checked.append(f"{mode}:{k.key}")
            if mode == "results":
                assert any("t Raw/20 °C" in line for line in lines), lines
    assert len(checked) >= 40, checked


def test_results_range_column_and_serials_placeholder_whole(cfg, wait_until, recorded_session):
    asyncio.run(_results_columns(cfg, wait_until, recorded_session))


async def _results_columns(cfg, wait_until, session):
    app = StationApp(cfg, autoconnect=False)
    async with app.run_test(size=SMALL) as pilot:
        await pilot.press("f3")
        await wait_until(pilot, lambda: app.screen.MODE == "results", what="Results")
        app.screen.query_one("#session-path", Input).value = str(session)
        await pilot.click("#session-open")
        await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit")
        await pilot.pause()
        table = app.screen.query_one("#results-table", DataTable)
        labels = [str(c.label) for c in table.columns.values()]
        assert labels[:7] == ["Leg", "A", "E", "M", "B", "R", "Range→HO"]
        lines = screen_lines(app)
        header = next(i for i, line in enumerate(lines) if "Range→HO" in line)
        col = lines[header].index("Range→HO")
        right = table.region.right
        for leg, lf in app.analysis.model.legs.items():  # each leg's range before → held-out range, whole
            before = f"{lf.stats.range_before_um:.2f} →"
            after = f"{lf.stats.heldout_range_um:.2f}"
            row = next(i for i, line in enumerate(lines) if i > header and line[col:].startswith(before))
            assert col + len(before) <= right and lines[row + 1][col:].startswith(after), (lines[row], lines[row + 1])
        # the Serials placeholder whole, at 80x24 and at 120x40
        for size in (SMALL, (120, 40)):
            await pilot.resize_terminal(*size)
            await pilot.press("f2")
            await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="Sweep")
            await pilot.pause()
            serials = app.screen.query_one("#serials", Input)
            assert len(serials.placeholder) <= serials.content_region.width, (size, serials.content_region)
            assert any(serials.placeholder in line for line in screen_lines(app))
            await pilot.press("f3")


def test_the_quit_dialog_is_on_top_and_the_plot_spans_the_leg(cfg, connected, wait_until):
    asyncio.run(_quit_on_top(cfg, connected, wait_until))


async def _quit_on_top(cfg, connected, wait_until):
    from tests.tooling import start_paper_sweep

    app = StationApp(cfg, time_scale=0.02, hide_volatile=True)
    async with app.run_test(size=SMALL) as pilot:
        await connected(pilot)
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep page")
        await start_paper_sweep(pilot, "2")
        await wait_until(pilot, lambda: app.sweep.done >= 1, 30, "the first point")
        await pilot.pause(0.2)
        # the plot's x axis spans the leg's targets (-90 .. +90 mm) from its first point, not -45..-135
        plot = app.screen.query_one("#sweep-plot")
        assert plot.drawn_xlim is not None and plot.drawn_xlim[0] <= -90.0 and plot.drawn_xlim[1] >= 90.0
        assert plot.drawn_xlim[1] - plot.drawn_xlim[0] < 200.0
        # notifications, then quit: the dialog and its buttons are not covered
        for i in range(4):
            app.notify(f"a long notification {i} " * 4, severity="warning", timeout=30)
        await pilot.press("ctrl+q")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="the quit question")
        dialog = app.screen
        # laid out: the dialog is pushed before it is composed and placed (a fixed pause was not that)
        await wait_until(pilot, lambda: all(dialog.query(sel) and dialog.query_one(sel).region.area > 0
                                            for sel in ("#confirm-yes", "#confirm-no", "#confirm-question")),
                         what="the quit dialog laid out")
        for selector in ("#confirm-yes", "#confirm-no", "#confirm-question"):
            widget = dialog.query_one(selector)
            region = widget.region
            for x, y in ((region.x, region.y), (region.right - 1, region.bottom - 1),
                         (region.x + region.width // 2, region.y + region.height // 2)):
                under, _ = dialog.get_widget_at(x, y)
                assert under is widget or widget in under.ancestors, f"{selector} is covered by {under!r} at {x},{y}"
        box = dialog.query_one("#confirm-dialog").region
        assert not any("a long notification" in line[box.x:box.right] for line in screen_lines(app)[box.y:box.bottom])
        await pilot.press("n")
        await wait_until(pilot, lambda: not isinstance(app.screen, ConfirmScreen), what="the question closed")
        app.action_abort_sweep()
        await wait_until(pilot, lambda: not app.sweep.active, 30, "the abort")
