"""The app's pages (one Textual mode per task) and the keys that work on every page: F1-F8, help, quit."""

from __future__ import annotations

from textual.binding import Binding

from station.tui.screens.compensation import CompensationScreen
from station.tui.screens.diagnosis import DiagnosisScreen
from station.tui.screens.help import HelpScreen
from station.tui.screens.history import HistoryScreen
from station.tui.screens.platform import PlatformScreen
from station.tui.screens.replay import ReplayScreen
from station.tui.screens.results import ResultsScreen
from station.tui.screens.rig import RigScreen
from station.tui.screens.sweep import SweepScreen

# mode -> its page (the order and keys of the tab bar: station.tui.screens.common.PAGES)
PAGE_MODES = {
    "rig": RigScreen,
    "sweep": SweepScreen,
    "results": ResultsScreen,
    "compensation": CompensationScreen,
    "replay": ReplayScreen,
    "diagnosis": DiagnosisScreen,
    "platform": PlatformScreen,
    "history": HistoryScreen,
}

# The page keys (F1-F8) are shown in the tab bar at the top of every page; the footer keeps
# the current page's actions, the help (?, F12: every page's keys) and quit.
APP_KEYS = [
    Binding("f1", "switch_mode('rig')", "Rig", show=False),
    Binding("f2", "switch_mode('sweep')", "Sweep", show=False),
    Binding("f3", "switch_mode('results')", "Results", show=False),
    Binding("f4", "switch_mode('compensation')", "Compensation", show=False),
    Binding("f5", "switch_mode('replay')", "Replay", show=False),
    Binding("f6", "switch_mode('diagnosis')", "Diagnosis", show=False),
    Binding("f7", "switch_mode('platform')", "Platform", show=False),
    Binding("f8", "switch_mode('history')", "History", show=False),
    Binding("question_mark", "station_help", "Help", key_display="?"),
    Binding("f12", "station_help", "Help", show=False),
    Binding("ctrl+q", "quit", "Quit", priority=True),
    Binding("ctrl+c", "quit", "Quit", show=False, priority=True),
]


class PageKeys:
    """The app's part that answers the keys of APP_KEYS beyond Textual's own (switch_mode, quit:
    station.tui.job_control.JobControl)."""

    def action_station_help(self) -> None:
        """Open the key help (every page's keys, from their BINDINGS), or close it when open."""
        if isinstance(self.screen, HelpScreen):
            self.screen.dismiss()
        else:
            self.push_screen(HelpScreen())
