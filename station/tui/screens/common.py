"""Pieces shared by the screens: the page frame and the confirmation dialog."""

from __future__ import annotations

import time

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

    GUTTER = 2  # cells between two columns of keys, so "h Home (0 mm)" and "r Reset fault" never touch

    def fit(self, keys=None, force: bool = False) -> None:
        """One row when the keys fit the terminal's width; else a grid of as few rows as fit
        (two at 80 columns for the Rig page's twelve keys), each column as wide as its widest
        key and GUTTER cells from the next, so every key is whole and apart from the next."""
        keys = list(self.query("FooterKey")) if keys is None else keys
        # each key as drawn compact: "k description"
        widths = [len(k.key_display or k.key) + 1 + len(k.description) for k in keys if hasattr(k, "description")]
        width = self.app.size.width
        rows = 1
        if 0 < width < sum(w + self.GUTTER for w in widths):  # one row: each key GUTTER cells from the next
            for rows in (2, 3, 4):
                columns = -(-len(widths) // rows)
                # the grid fills row by row: column j holds keys j, j + columns, ...
                need = sum(max(widths[j::columns]) for j in range(columns)) + self.GUTTER * (columns - 1)
                if need <= width:
                    break
        columns = max(1, -(-len(keys) // rows))
        if not force and (rows, columns) == getattr(self, "_fitted", None):
            return  # as laid out: no new layout (the keys stay where they are)
        self._fitted = (rows, columns)
        self.set_class(rows > 1, "-two-rows")
        self.styles.layout = "grid" if rows > 1 else "horizontal"
        self.styles.grid_size_columns = columns
        self.styles.height = rows


class FieldRefusal(Static):
    """The refusals of the value fields `fields` (ids of station.tui.fields.ValueField), in red
    under them: what is wrong and what to type, as the command line says it. Hidden while every
    one of them reads. The page re-checks it on each key typed (StationScreen.on_input_changed)."""

    DEFAULT_CSS = "FieldRefusal { height: auto; color: $error; }"

    def __init__(self, *fields: str, **kwargs) -> None:
        super().__init__("", markup=False, **kwargs)
        self.fields = fields

    def on_mount(self) -> None:
        self.check()

    def check(self) -> None:
        texts = []
        for wid in self.fields:
            for field in self.screen.query(f"#{wid}"):
                refusal = getattr(field, "refusal", "")
                if refusal and not field.disabled:
                    texts.append(refusal)
        self.update("\n".join(texts))
        self.display = bool(texts)


class StationScreen(Screen):
    """A page: header (no clock), page tabs, a line saying what the page is for, body, footer."""

    MODE = ""
    PAGE_HELP = ""
    # Focus a table or button, not a text field, so the letter keys in the footer act at once.
    AUTO_FOCUS = "DataTable, Button"
    BINDINGS = [Binding("escape", "leave_field", "Leave field", show=False)]
    # Keys that act on the rig (connect, enable, move, start a sweep, push a table): the names of
    # their actions on this page. Such a key acts only when it is pressed on its own (docs/tui.md,
    # "Keys"): not within STRAY_HOLD_S after a key this page does not bind (typing meant for a
    # field: "abc" must not press c) or after a text field lost the focus, and not when another
    # key follows it within ALONE_S ("hello" must not home a leg; "-25" must not jog). The same
    # key pressed again and again (+ + + to jog) acts each time. Stop, abort and quit never wait.
    RIG_KEYS: frozenset[str] = frozenset()
    STRAY_HOLD_S = 1.0
    ALONE_S = 0.3

    # -- keys act only when pressed on their own (RIG_KEYS) ----------------------------------------
    _stray_at = -1e9  # time.monotonic() of the last key typed outside a field that this page does not bind
    _stray_text = ""  # those keys, for the notification
    _pending = None  # (key, binding, timer) of a rig key waiting ALONE_S to act

    def _binding_for(self, event: events.Key):
        for _node, bindings in self._modal_binding_chain:
            for key in (event.key, *event.aliases):
                for binding in bindings.key_to_bindings.get(key, ()):
                    return binding
        return None

    @staticmethod
    def _action_name(action: str) -> str:
        return action.split("(", 1)[0].removeprefix("app.").removeprefix("screen.")

    def on_key(self, event: events.Key) -> None:
        """Keys that reached the page (a text field keeps what it takes): a rig key waits to see
        whether it was pressed on its own; any other key typed here counts as stray typing."""
        now = time.monotonic()
        binding = self._binding_for(event)
        pending, self._pending = self._pending, None
        if pending is not None:
            key, pending_binding, timer = pending
            timer.stop()
            if key == event.key:  # the same key again (+ + +): the first acts now
                self._run_binding(pending_binding)
            else:  # another key within ALONE_S: the rig key was part of a word typed here
                self._stray_at, self._stray_text = now, (self._stray_text + key)[-12:]
                self._ignored(key, pending_binding, "another key followed it at once")
        if binding is None:
            if event.is_printable:
                if now - self._stray_at > self.STRAY_HOLD_S:
                    self._stray_text = ""
                self._stray_at, self._stray_text = now, (self._stray_text + (event.character or ""))[-12:]
            return
        if self._action_name(binding.action) not in self.RIG_KEYS:
            return
        event.stop()
        event.prevent_default()  # the app's binding does not run now: it runs from here, or not at all
        if now - self._stray_at <= self.STRAY_HOLD_S:
            self._stray_at = now  # still typing
            self._ignored(event.key, binding, "it came right after typing outside a field"
                          + (f" ({self._stray_text})" if self._stray_text.strip() else ""))
            return
        timer = self.set_timer(self.ALONE_S, lambda: self._alone(event.key))
        self._pending = (event.key, binding, timer)

    def _alone(self, key: str) -> None:
        pending = self._pending
        if pending is not None and pending[0] == key:
            self._pending = None
            self._run_binding(pending[1])

    def _run_binding(self, binding) -> None:
        # from the page's message queue, as a key's binding runs (a dialog it opens is the page's)
        self.call_later(self.run_action, binding.action)

    def _ignored(self, key: str, binding, why: str) -> None:
        shown = binding.key_display or key
        self.notify(f"{shown} ({binding.description}) ignored: {why}. Nothing was done; press {shown} on its own "
                    "to do it (Esc leaves a text field).", title="Key ignored", severity="warning", timeout=6)

    def on_descendant_blur(self, event: events.DescendantBlur) -> None:
        from textual.widgets import Input

        if isinstance(event.widget, Input):  # the next letters may still be meant for the field
            self._stray_at = time.monotonic()

    def on_screen_suspend(self) -> None:
        pending, self._pending = self._pending, None
        if pending is not None:  # a dialog or another page came first: the key does nothing
            pending[2].stop()

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

    def on_input_changed(self, event) -> None:
        # a value field's refusal line follows each key typed (a subclass's own handler runs too)
        for line in self.query(FieldRefusal).results(FieldRefusal):
            line.check()

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
        # the safe answer is the default; no button when the app is closing as the dialog mounts
        for button in self.query("#confirm-no").results(Button):
            button.focus()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.dismiss(event.button.id == "confirm-yes")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)
