"""Steps the TUI tests take the way a user does (through keys, fields and buttons)."""

from __future__ import annotations

from textual.widgets import Input


async def open_session(pilot, wait_until, mode_key: str, path) -> None:
    """Go to the page of `mode_key` (e.g. "f3" Results), type `path` into its session picker and
    press Open. `wait_until` is the conftest fixture's bounded wait."""
    app = pilot.app
    await pilot.press(mode_key)
    await wait_until(pilot, lambda: app.screen.query("#session-path"), what="the session picker")
    app.screen.query_one("#session-path", Input).value = str(path)
    await pilot.click("#session-open")
