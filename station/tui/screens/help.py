"""The key help (`?` or F12 on every page): every page with its keys, and the keys that work
everywhere. The keys are read from the screens' and the app's BINDINGS, so the help says what
the keys do today, not what they did when it was written."""

from __future__ import annotations

import re

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical, VerticalScroll
from textual.screen import ModalScreen, Screen
from textual.widgets import Static

from station.tui.screens.common import PAGES, StationScreen


def _bindings_of(classes) -> list[Binding]:
    """The bindings the classes' own BINDINGS declare (comma-separated keys split), in order;
    a key bound by an earlier class (a subclass) hides the same key further on, as in Textual."""
    out: list[Binding] = []
    seen: set[str] = set()
    for cls in classes:
        for b in Binding.make_bindings(cls.__dict__.get("BINDINGS", [])):
            if b.key not in seen:
                seen.add(b.key)
                out.append(b)
    return out


def page_bindings(screen_cls: type[Screen]) -> list[Binding]:
    """A page's own keys: the BINDINGS of its classes (mixins too) below StationScreen, the
    subclass's first."""
    shared = set(StationScreen.__mro__)
    return _bindings_of(c for c in screen_cls.__mro__ if c not in shared)


def global_bindings(app) -> list[Binding]:
    """The keys that work on every page: the app's (but the page keys F1-F7, listed with the
    pages) and StationScreen's."""
    return [b for b in _bindings_of([*type(app).__mro__, StationScreen])
            if not b.action.startswith("switch_mode(") and not b.system]


def key_display(app, binding: Binding) -> str:
    """The key as the footer shows it, function keys as printed on the keyboard (F12)."""
    shown = app.get_key_display(binding)
    return shown.upper() if re.fullmatch(r"f\d{1,2}", shown) else shown


# Key entries are laid out in lines of at most this many cells, so a line breaks between entries,
# not inside one (the dialog is wider; a narrower terminal wraps further).
KEYS_WIDTH = 96


def _item(keys: str, text: str) -> str:
    """One 'KEYS text' entry."""
    return f"[b]{keys}[/b] {text}"


def _lines_of(items: list[str], width: int = KEYS_WIDTH) -> str:
    """`items` three spaces apart, broken into lines between items."""
    lines: list[list[str]] = [[]]
    used = 0
    for item in items:
        n = Text.from_markup(item).cell_len
        if lines[-1] and used + 3 + n > width:
            lines.append([])
            used = 0
        used += n + (3 if lines[-1] else 0)
        lines[-1].append(item)
    return "\n".join("   ".join(line) for line in lines)


def key_lines(app, bindings: list[Binding]) -> list[str]:
    """'KEYS description' per action (the keys of one action joined with ' / '), in order."""
    keys: dict[tuple[str, str], list[str]] = {}
    for b in bindings:
        if not b.description:
            continue
        shown = key_display(app, b)
        # the longer words of a key whose footer label is short (Results: t "Raw/20 °C")
        group = keys.setdefault((b.action, b.tooltip or b.description), [])
        if shown not in group:
            group.append(shown)
    return [_item(" / ".join(k), desc) for (_, desc), k in keys.items()]


def help_sections(app, width: int = KEYS_WIDTH) -> list[tuple[str, str]]:
    """(heading, keys) per page (its key, title and what it is for; its keys), then the keys
    that work everywhere; the keys in lines of at most `width` cells."""
    out = []
    for mode, key, title in PAGES:
        screen_cls = app.MODES.get(mode)
        if screen_cls is None:
            continue
        about = getattr(screen_cls, "PAGE_HELP", "")
        keys = key_lines(app, page_bindings(screen_cls))
        out.append((f"[reverse b] {key} [/reverse b] [b]{title}[/b]" + (f"  [dim]{about}[/dim]" if about else ""),
                    _lines_of(keys, width) if keys else "[dim](no keys of its own)[/dim]"))
    out.append(("[b u]Everywhere[/b u]", _lines_of([_item(f"{PAGES[0][1]}..{PAGES[-1][1]}", "pages"),
                                                    *key_lines(app, global_bindings(app)),
                                                    _item("tab / shift+tab", "next / previous field")], width)))
    return out


def help_text(app) -> str:
    """The whole help as one text (what the help screen shows)."""
    return "\n".join(f"{heading}\n{keys}" for heading, keys in help_sections(app))


class HelpScreen(ModalScreen[None]):
    """The key help; Esc, q (or ? / F12 again) closes it. While it is shown no other key acts
    (the app's keys stop at a modal screen), but the priority ones (Ctrl+Q)."""

    BINDINGS = [
        Binding("escape,q,question_mark,f12", "close", "Close"),
    ]

    def compose(self) -> ComposeResult:
        with Vertical(id="help-dialog"):
            yield Static("[b]Keys of the station UI[/b]", id="help-title")
            with VerticalScroll(id="help-scroll"):
                yield Static("[dim]A page's letter keys act when the focus is not in a text field (Esc leaves "
                             "it).[/dim]")
                # the dialog's border and padding, the keys' indent, the scroll bar: 12 cells
                for heading, keys in help_sections(self.app, min(KEYS_WIDTH, self.app.size.width - 12)):
                    yield Static(heading, classes="help-heading")
                    yield Static(keys, classes="help-keys")
            yield Static("[dim]Esc or q closes this help[/dim]", id="help-close")

    def on_mount(self) -> None:
        self.query_one("#help-scroll").focus()  # the arrows scroll it

    def action_close(self) -> None:
        self.dismiss()
