"""Pieces shared by the screens: the page frame and the confirmation dialog."""

from __future__ import annotations

from rich.text import Text
from textual import events
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Grid, Horizontal, VerticalScroll
from textual.screen import ModalScreen, Screen
from textual.widgets import Button, Footer, Header, Label, Static


PAGES = [("rig", "F1", "Rig"), ("sweep", "F2", "Sweep"), ("results", "F3", "Results"),
         ("compensation", "F4", "Compensation"), ("replay", "F5", "Replay"), ("diagnosis", "F6", "Diagnosis"),
         ("platform", "F7", "Platform"), ("history", "F8", "History")]


# Shorter page titles for the tab bar of a narrow terminal (the help keeps the full ones).
SHORT_TITLES = {"compensation": "Comp", "diagnosis": "Diag", "platform": "Platf", "history": "Hist"}

# Below these sizes (cells) a page is laid out for a small terminal (an 80x24 bench laptop, an
# SSH session): the screen gets the class "-narrow" / "-short", which station.tcss styles
# (controls on two rows, no margins, smaller plots, no title bar, ...).
NARROW_WIDTH = 120
SHORT_HEIGHT = 32


def nav_bar(current: str, width: int | None = None) -> str:
    """The page tabs with their keys; the current page highlighted. Given the `width` (cells)
    it has, the widest form that fits: spaced, tight, short titles, then only the current
    page's title; every page's key is always there."""
    def tabs(spaced: bool, titles) -> str:
        pad = " " if spaced else ""
        parts = []
        for mode, key, title in PAGES:
            title = titles(mode, title)
            text = f"{key} {title}" if title else key
            if mode == current:
                parts.append(f"[reverse b]{pad}{text}{pad}[/reverse b]")
            else:
                parts.append(f"{pad}[b]{key}[/b]{' ' + title if title else ''}{pad}")
        return "│".join(parts)

    forms = [tabs(True, lambda m, t: t), tabs(False, lambda m, t: t),
             tabs(False, lambda m, t: SHORT_TITLES.get(m, t)),
             tabs(False, lambda m, t: t if m == current else "")]
    if width is None:
        return forms[0]
    for form in forms:
        if Text.from_markup(form).cell_len <= width:
            return form
    return forms[-1]


class StationFooter(Footer):
    """The footer; on a narrow terminal the help key (?) stays on show at its right end, however
    many keys the page has (the help lists them all)."""

    def compose(self) -> ComposeResult:
        keys = []
        for widget in super().compose():
            if getattr(widget, "key", None) == "question_mark":  # a FooterKey
                widget.add_class("-help-key")
            keys.append(widget)
            yield widget
        self.fit(keys, force=True)  # Footer.compose has just set its own grid columns

    def fit(self, keys=None, force: bool = False) -> None:
        """Two rows (a grid of the keys) when one row of the terminal's width would cut keys off
        (the Rig page's twelve at 80 columns), one row otherwise."""
        keys = list(self.query("FooterKey")) if keys is None else keys
        # each key as drawn compact: "k description", a space after it
        need = sum(len(k.key_display or k.key) + 1 + len(k.description) + 1 for k in keys if hasattr(k, "description"))
        width = self.app.size.width
        two_rows = 0 < width < need
        columns = max(1, -(-len(keys) // 2)) if two_rows else max(1, len(keys))
        if not force and (two_rows, columns) == getattr(self, "_fitted", None):
            return  # as laid out: no new layout (the keys stay where they are)
        self._fitted = (two_rows, columns)
        self.set_class(two_rows, "-two-rows")
        self.styles.layout = "grid" if two_rows else "horizontal"
        self.styles.grid_size_columns = columns
        self.styles.height = 2 if two_rows else 1


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
        yield Static(nav_bar(self.MODE, self.app.size.width or None), classes="nav-bar")
        yield Static(f"[dim]{self.PAGE_HELP}[/dim]", classes="page-help")

    def compose_footer(self) -> ComposeResult:
        yield StationFooter(show_command_palette=False, compact=True)

    # -- small terminals ---------------------------------------------------------------------------
    _fitted: tuple[int, int] | None = None  # the terminal size the page was last laid out for

    @property
    def narrow(self) -> bool:
        """The terminal is narrower than NARROW_WIDTH."""
        return 0 < self.app.size.width < NARROW_WIDTH

    @property
    def short(self) -> bool:
        """The terminal is shorter than SHORT_HEIGHT."""
        return 0 < self.app.size.height < SHORT_HEIGHT

    def fit_to_size(self) -> None:
        """Set the classes -narrow / -short for the terminal's size and the tab bar for its
        width; call `size_changed` when the size is not the one the page was laid out for (not
        the first time: a page draws itself for the size it has when it is mounted)."""
        self.set_class(self.narrow, "-narrow")
        self.set_class(self.short, "-short")
        for bar in self.query(".nav-bar").results(Static):
            bar.update(nav_bar(self.MODE, self.app.size.width or None))
        for footer in self.query(StationFooter).results(StationFooter):
            footer.fit()
        before, self._fitted = self._fitted, tuple(self.app.size)
        if before is not None and before != self._fitted:
            self.size_changed()

    def size_changed(self) -> None:
        """Hook: the terminal has another size (`self.narrow`, `self.short`; e.g. the columns of
        a table that fit)."""

    def on_mount(self) -> None:
        self.fit_to_size()

    def on_resize(self, event: events.Resize) -> None:
        self.fit_to_size()

    def on_screen_resume(self) -> None:
        # a page not on show was not told of a resize
        self.fit_to_size()

    # -- pages that analyse a session (a SessionPicker) follow the newest recording -------------
    def follow_sessions(self) -> None:
        """Offer each new recording in this page's SessionPicker, starting with the latest."""
        self.app.session_listeners.append(self._on_new_session)
        if self.app.last_session is not None:
            self._on_new_session(self.app.last_session)

    def action_open_session(self) -> None:
        """Open the session the page's picker names (its Open button; ctrl+o on the pages that
        have one: a control key, so it acts from the path field too)."""
        from station.tui.widgets import SessionPicker

        for picker in self.query(SessionPicker).results(SessionPicker):
            picker.choose()
            return

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
            with VerticalScroll(id="confirm-scroll"):  # a long question scrolls (Tab, arrows); the buttons stay
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
