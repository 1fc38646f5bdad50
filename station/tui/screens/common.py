"""Pieces shared by the screens: the page frame and the confirmation dialog."""

from __future__ import annotations

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Grid, Horizontal
from textual.screen import ModalScreen, Screen
from textual.widgets import Button, Footer, Header, Label, Static


PAGES = [("rig", "F1", "Rig"), ("sweep", "F2", "Sweep"), ("results", "F3", "Results"),
         ("compensation", "F4", "Compensation"), ("replay", "F5", "Replay"), ("diagnosis", "F6", "Diagnosis"),
         ("platform", "F7", "Platform")]


def nav_bar(current: str) -> str:
    """The page tabs with their keys; the current page highlighted."""
    parts = []
    for mode, key, title in PAGES:
        if mode == current:
            parts.append(f"[reverse b] {key} {title} [/reverse b]")
        else:
            parts.append(f" [b]{key}[/b] {title} ")
    return "│".join(parts)


class StationScreen(Screen):
    """A page: header (no clock), page tabs, a line saying what the page is for, body, footer."""

    MODE = ""
    PAGE_HELP = ""
    # Focus a table or button, not a text field, so the letter keys in the footer act at once.
    AUTO_FOCUS = "DataTable, Button"
    BINDINGS = [Binding("escape", "leave_field", "Leave field", show=False)]

    def action_leave_field(self) -> None:
        """Leave a text field (Esc) so the letter keys act again."""
        for selector in ("DataTable", "Button"):
            for widget in self.query(selector):
                if widget.focusable:
                    widget.focus()
                    return

    def compose_header(self) -> ComposeResult:
        yield Header(show_clock=False, icon="≡")
        yield Static(nav_bar(self.MODE), classes="nav-bar")
        yield Static(f"[dim]{self.PAGE_HELP}[/dim]", classes="page-help")

    def compose_footer(self) -> ComposeResult:
        yield Footer(show_command_palette=False, compact=True)

    # -- pages that analyse a session (a SessionPicker) follow the newest recording -------------
    def follow_sessions(self) -> None:
        """Offer each new recording in this page's SessionPicker, starting with the latest."""
        self.app.session_listeners.append(self._on_new_session)
        if self.app.last_session is not None:
            self._on_new_session(self.app.last_session)

    def _on_new_session(self, path) -> None:
        from station.tui.widgets import SessionPicker

        picker = self.query_one(SessionPicker)
        picker.rescan()
        picker.set_path(path)


class ConfirmScreen(ModalScreen[bool]):
    """Yes/no question; dismisses with True only on an explicit yes."""

    BINDINGS = [
        Binding("y", "answer(True)", "Yes"),
        Binding("n", "answer(False)", "No"),
        Binding("escape", "answer(False)", "Cancel"),
    ]

    def __init__(self, question: str, yes: str = "Yes", no: str = "No") -> None:
        super().__init__()
        self.question = question
        self.yes_label = yes
        self.no_label = no

    def compose(self) -> ComposeResult:
        with Grid(id="confirm-dialog"):
            yield Label(self.question, id="confirm-question")
            with Horizontal(id="confirm-buttons"):
                yield Button(f"{self.yes_label} (y)", variant="error", id="confirm-yes")
                yield Button(f"{self.no_label} (n)", variant="primary", id="confirm-no")

    def on_mount(self) -> None:
        self.query_one("#confirm-no", Button).focus()  # the safe answer is the default

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.dismiss(event.button.id == "confirm-yes")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)
