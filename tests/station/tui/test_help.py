"""The key help: `?` / F12 on every page (and in every footer), every page's keys read from the
screens' BINDINGS (so it never goes stale), the global keys; Esc / q close it."""

from __future__ import annotations

import asyncio

import pytest
from rich.text import Text
from textual.binding import Binding
from textual.widgets import Static
from textual.widgets._footer import FooterKey

from station.tui.app import StationApp
from station.tui.screens.common import PAGES
from station.tui.screens.help import HelpScreen, help_text, key_display, page_bindings
from station.tui.screens.rig import RigScreen

pytestmark = pytest.mark.timeout(120)


def shown_text(screen: HelpScreen) -> str:
    return "\n".join(str(w.render()) for w in screen.query(Static))


def test_help_lists_every_page_its_keys_and_the_global_keys_and_closes(cfg, size, wait_until):
    asyncio.run(_help(cfg, size, wait_until))


async def _help(cfg, size, wait_until):
    app = StationApp(cfg, autoconnect=False, hide_volatile=True)
    async with app.run_test(size=size) as pilot:
        # every page shows the help key in its footer, and F12 opens it there
        for mode, key, title in PAGES:
            await pilot.press(key.lower())
            await wait_until(pilot, lambda: getattr(app.screen, "MODE", "") == mode, what=f"the {title} page")
            await wait_until(pilot, lambda: any(k.action == "station_help" and k.key_display == "?"
                                                for k in app.screen.query(FooterKey)), what=f"? Help in the {title} footer")
            await pilot.press("f12")
            await wait_until(pilot, lambda: isinstance(app.screen, HelpScreen), what=f"the help on {title}")
            await pilot.press("escape")
            await wait_until(pilot, lambda: not isinstance(app.screen, HelpScreen), what="the help to close (Esc)")
            assert app.screen.MODE == mode

        await pilot.press("f1")
        await wait_until(pilot, lambda: app.screen.MODE == "rig", what="the Rig page")
        await pilot.press("question_mark")
        await wait_until(pilot, lambda: isinstance(app.screen, HelpScreen), what="the help (?)")
        text = shown_text(app.screen)
        # every page, with each of its keys as its screen class binds it today
        for mode, key, title in PAGES:
            assert f" {key} " in text and title in text
            for b in page_bindings(app.MODES[mode]):
                # a key whose footer label is short (Results' t) has its longer words in the help
                assert f"{key_display(app, b)} {b.tooltip or b.description}" in text, (title, b)
        for needed in ("m Move to", "+ Jog +", "- Jog −", "j Jog step", "x Stop all", "r Resume aborted",
                       "F1..F8 pages", "? / F12 Help", "^q", "Quit", "esc Leave field"):
            assert needed in text, needed
        await pilot.press("q")
        await wait_until(pilot, lambda: not isinstance(app.screen, HelpScreen), what="the help to close (q)")
        # ? toggles it
        await pilot.press("question_mark")
        await wait_until(pilot, lambda: isinstance(app.screen, HelpScreen), what="the help (?)")
        await pilot.press("question_mark")
        await wait_until(pilot, lambda: not isinstance(app.screen, HelpScreen), what="the help to close (?)")
        assert app.screen.MODE == "rig"


class KnockingRig(RigScreen):
    BINDINGS = [Binding("k", "knock", "Knock twice")]


class KnockingApp(StationApp):
    MODES = {**StationApp.MODES, "rig": KnockingRig}


def test_the_help_reads_the_keys_from_the_screens_bindings(cfg):
    """A key added to a page's BINDINGS (here in a subclass) is in the help without touching it;
    the page's inherited keys are there too."""
    app = KnockingApp(cfg, autoconnect=False)
    text = Text.from_markup(help_text(app)).plain
    assert "k Knock twice" in text and "x Stop all" in text and "e Enable" in text
    assert "? / F12 Help" in text and "^q / ^c Quit" in text
