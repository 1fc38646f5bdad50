"""Replay screen: pick a recorded session (recordings/, the runs folder, or a path), see what it
holds, open it on the Results and Diagnosis screens, or replay it at a chosen speed through the
same sweep screen once replay devices are installed (see station.tui.capabilities).

The faults the session recorded (/faults: every retry and the point given up) are listed in a
table; after a replay of the session on show, the replayed run's faults are listed under them,
so the two can be compared. Sessions are read in a thread worker, never on the UI thread: a
damaged file is refused by the reader within seconds and said in a notification.
"""

from __future__ import annotations

from pathlib import Path

from textual import work
from rich.markup import escape
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import Button, DataTable, Input, Label, Static

from procedures.vocabulary import InputError
from station.tui import capabilities
from station.tui.error_text import describe
from station.tui.fields import FIELD_KINDS, ValueField
from station.tui.screens.common import FieldRefusal, StationScreen
from station.tui.widgets import SessionPicker, fit_columns, sample_folders


class SessionRead(Message):
    """A session read for the page (`replayed`: the output of a replay of `source`)."""

    def __init__(self, path: Path, session=None, error: str = "", replayed: bool = False,
                 source: Path | None = None) -> None:
        super().__init__()
        self.path = path
        self.session = session
        self.error = error
        self.replayed = replayed
        self.source = source


FAULT_COLUMNS = ("Session", "Point", "Leg", "Run", "Target mm", "Time s", "Kind", "Attempt", "Gave up", "Message")
# A narrow terminal: shorter labels, the kind and the start of the message beside the leg and
# run; where and when last. (The message is long: the table scrolls sideways for the rest.)
NARROW_FAULT_COLUMNS = (("Session", "Leg", "Run", "Pt", "Kind", "Try", "Gave up", "Message", "Target mm", "Time s"),
                        (0, 2, 3, 1, 6, 7, 8, 9, 4, 5))
MESSAGE_SHOWN = 30  # cells of the message the full columns must leave room for


def fault_rows(recording, session: str) -> list[tuple[str, ...]]:
    """One row per fault record of `recording` (station.services.replay_job.Recording), labelled `session`."""
    return recording.fault_rows(session)


class ReplayScreen(StationScreen):
    MODE = "replay"
    PAGE_HELP = "recorded sessions: inspect, analyse (Results, Diagnosis), or replay through the sweep"
    BINDINGS = [
        Binding("ctrl+o", "open_session", "Open", key_display="^o"),
        Binding("o", "open_results", "Open in Results"),
        Binding("d", "open_diagnosis", "Diagnose"),
        Binding("r", "replay", "Replay"),
    ]
    CSS = """
    #replay-faults { height: auto; max-height: 14; margin: 1 0 0 0; }
    """

    def compose(self) -> ComposeResult:
        yield from self.compose_header()
        with Vertical(id="replay-body"):
            yield SessionPicker(lambda: [*sample_folders(), self.app.cfg.recordings_dir], id="replay-picker")
            with Horizontal(classes="controls"):
                yield Label("Speed ")
                yield ValueField("max", id="replay-speed", kind=FIELD_KINDS["replay-speed"][0], where="speed", blank=None,
                                 compact=True, tooltip="1 = real time, N = N times faster, max (or blank) = as fast "
                                                       "as possible, as station replay --speed")
                yield Button("Replay (r)", id="replay-run", compact=True, variant="success")
                yield Button("Open in Results (o)", id="replay-results", compact=True)
                yield Button("Diagnose (d)", id="replay-diagnose", compact=True)
            yield FieldRefusal("replay-speed", id="replay-speed-refusal")
            yield Static("choose a session above (sample sessions live in recordings/)", id="replay-info", classes="status")
            yield DataTable(id="replay-faults", cursor_type="row", zebra_stripes=True)
        yield from self.compose_footer()

    def on_mount(self) -> None:
        self.session = None
        self.session_path: Path | None = None
        self._reading: Path | None = None  # the last file asked for: an earlier read's answer is dropped
        self.replay_source: Path | None = None  # the session the last replay started here replayed
        self.replayed = None  # the replay's recorded session (its faults are listed), for replay_source
        self.replayed_path: Path | None = None
        self.info_lines: list[str] = []  # what #replay-info says of the session on show
        self._show_faults()
        if self.app.replay_path is not None:
            self.query_one(SessionPicker).set_path(self.app.replay_path)
            self._read(self.app.replay_path)
        elif self.app.last_session is not None:  # F5 after a sweep: that session, opened
            self.query_one(SessionPicker).set_path(self.app.last_session)
            self._read(self.app.last_session)
        self.app.session_listeners.append(self._on_new_session)

    def _on_new_session(self, path: Path) -> None:
        picker = self.query_one(SessionPicker)
        picker.rescan()
        if path != self.session_path:
            picker.set_path(path)
            if self.session is None and self._reading is None:  # nothing open here: open it
                self._read(path)
        sweep = self.app.sweep
        source = self.replay_source
        if source is not None and sweep.out == path and sweep.label == f"replay of {source.name}":
            self._read_replayed(path, source)  # the replay started here has ended: list its faults

    def on_session_picker_chosen(self, message: SessionPicker.Chosen) -> None:
        self._read(message.path)

    def _read(self, path: Path) -> None:
        self._reading = path
        self._read_worker(path)

    @work(thread=True, exclusive=True, group="replay-read", exit_on_error=False)
    def _read_worker(self, path: Path) -> None:
        try:
            from station.services.replay_job import read_recording

            self.post_message(SessionRead(path, read_recording(path)))
        except Exception as exc:
            self.post_message(SessionRead(path, error=describe(exc, f"cannot read {path.name}")))

    @work(thread=True, exclusive=True, group="replay-read-replayed", exit_on_error=False)
    def _read_replayed(self, path: Path, source: Path) -> None:
        try:
            from station.services.replay_job import read_recording

            self.post_message(SessionRead(path, read_recording(path), replayed=True, source=source))
        except Exception as exc:
            self.post_message(SessionRead(path, error=describe(exc, f"cannot read the replay {path.name}"),
                                          replayed=True, source=source))

    def on_session_read(self, message: SessionRead) -> None:
        if message.replayed:
            self._replayed_read(message)
            return
        if message.path != self._reading:  # the answer to an earlier Open: another file is on its way
            return
        info = self.query_one("#replay-info", Static)
        if message.error:
            self.session = None
            info.update(f"[red]{message.error}[/red]")
            self._show_faults()
            self.notify(message.error, title="Replay", severity="error", timeout=12)
            return
        self.session = message.session
        self.session_path = message.path
        s = message.session.summary()
        targets = s["targets_mm"]
        name = message.path.name if self.app.hide_volatile else str(message.path)
        lines = [
            f"[b]{name}[/b]",
            f"outcome [b]{s['outcome']}[/b]; {s['points']} points on legs {s['legs']}; {s['faults']} fault record(s)",
            f"plan {s['kind']}: {len(targets)} targets"
            + (f" {targets[0]:+.1f}..{targets[-1]:+.1f} mm" if targets else "")
            + f", {s['cycles']} cycles",
            f"rig {s['rig']}, operator {s['operator']}, schema {s['schema']}",
        ]
        if not self.app.hide_volatile:
            lines.append(f"recorded {s['started_utc']} .. {s['ended_utc']}")
        if capabilities.find("replay") is None:
            lines.append("[yellow]" + capabilities.missing_text("replay", "Replay through the drivers") +
                         "[/yellow] You can still analyse the session (o, d).")
        self.info_lines = lines
        info.update("\n".join(lines + self._replayed_lines()))
        self._show_faults()
        self.app.set_session(message.path)

    def _replayed_read(self, message: SessionRead) -> None:
        if message.source != self.replay_source:
            return
        if message.error:
            self.notify(message.error, title="Replay", severity="error", timeout=12)
            return
        self.replayed, self.replayed_path = message.session, message.path
        if self.session is not None and self.session_path == message.source:
            self.query_one("#replay-info", Static).update("\n".join(self.info_lines + self._replayed_lines()))
        self._show_faults()

    def _replayed_lines(self) -> list[str]:
        r = self.replayed
        if r is None or self.session is None or self.session_path != self.replay_source:
            return []
        name = self.replayed_path.name
        r = r.summary()
        return [f"replayed as [b]{name}[/b]: outcome [b]{r['outcome']}[/b]; {r['points']} points; "
                f"{r['faults']} fault record(s) (listed below as 'replayed')"]

    def _show_faults(self) -> None:
        """The faults of the session on show, then those of its replay (when replayed here)."""
        table = self.query_one("#replay-faults", DataTable)
        table.clear()
        rows = []
        if self.session is not None:
            rows = fault_rows(self.session, "recorded")
            if self.replayed is not None and self.session_path == self.replay_source:
                rows += fault_rows(self.replayed, "replayed")
        measured = [(*row[:-1], row[-1][:MESSAGE_SHOWN]) for row in rows]
        order = fit_columns(table, [(FAULT_COLUMNS, None), NARROW_FAULT_COLUMNS], measured, self.app.size.width - 2)
        for row in rows:
            table.add_row(*(row[i] for i in order))

    def size_changed(self) -> None:
        self._show_faults()  # the table's labels for the width

    # -- actions -------------------------------------------------------------------------------------
    async def on_button_pressed(self, event: Button.Pressed) -> None:
        action = {"replay-run": "replay", "replay-results": "open_results",
                  "replay-diagnose": "open_diagnosis"}.get(event.button.id or "")
        if action is not None:
            event.stop()
            await self.run_action(action)  # a coroutine: not awaited, the buttons did nothing

    def _need_session(self) -> bool:
        if self.session is None:
            self.notify("Choose a session first (Open).", severity="warning")
            return False
        return True

    async def action_open_results(self) -> None:
        if self._need_session():
            self.app.set_session(self.session_path)  # the session shown here, not the last one made
            await self.app.switch_mode("results")
            self.app.screen.action_fit()

    async def action_open_diagnosis(self) -> None:
        if self._need_session():
            self.app.set_session(self.session_path)
            await self.app.switch_mode("diagnosis")
            self.app.screen.action_diagnose()

    async def action_replay(self) -> None:
        if not self._need_session():
            return
        if capabilities.find("replay") is None:
            self.notify(capabilities.missing_text("replay", "Replay through the drivers"),
                        title="Replay", severity="warning", timeout=12)
            return
        try:  # the kind of station replay --speed (station.tui.fields.FIELD_KINDS)
            speed = self.query_one("#replay-speed", ValueField).read()
        except InputError as exc:  # the message names the field and says what to type
            self.notify(escape(f"{exc}; nothing replayed"), title="Replay", severity="error", timeout=10)
            return
        if self.app.start_replay(self.session_path, speed):
            self.replay_source, self.replayed, self.replayed_path = self.session_path, None, None
            self._show_faults()
            await self.app.switch_mode("sweep")
