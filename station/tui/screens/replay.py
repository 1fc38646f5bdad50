"""Replay screen (placeholder until its procedures land)."""

from __future__ import annotations

from textual.app import ComposeResult
from textual.widgets import Static

from station.tui.screens.common import StationScreen


class ReplayScreen(StationScreen):
    MODE = "replay"
    PAGE_HELP = ""

    def compose(self) -> ComposeResult:
        yield from self.compose_header()
        yield Static("not available yet")
        yield from self.compose_footer()
