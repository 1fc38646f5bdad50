"""Plots for the station UI (textual-plotext): change the plot through `.plt`, then refresh()."""

from __future__ import annotations

from typing import Sequence

from textual_plotext import PlotextPlot


class XYPlot(PlotextPlot):
    """A scatter/line plot of one or more series. `series` is a list of
    (label, x, y, style) with style "scatter" or "line". Remembers what it drew so tests and
    callers can tell whether it moved on (`drawn_points`)."""

    def __init__(self, title: str = "", xlabel: str = "", ylabel: str = "", **kwargs) -> None:
        super().__init__(**kwargs)
        self.title_text = title
        self.xlabel_text = xlabel
        self.ylabel_text = ylabel
        self.drawn_points = 0
        self.drawn_series: list[str] = []
        self.drawn_xlim: tuple[float, float] | None = None  # the x axis span set by show(xlim=...)

    def on_mount(self) -> None:
        super().on_mount()
        self.show([])

    def show(self, series: Sequence[tuple[str, Sequence[float], Sequence[float], str]], title: str | None = None,
             xlim: tuple[float, float] | None = None) -> None:
        """Draw `series`; `xlim` (lo, hi): the x axis spans at least that (e.g. a leg's whole
        stroke from its first point on), else plotext fits it to the points."""
        plt = self.plt
        plt.clear_data()
        plt.clear_figure()
        plt.title(self.title_text if title is None else title)
        plt.xlabel(self.xlabel_text)
        plt.ylabel(self.ylabel_text)
        n = 0
        names = []
        for label, x, y, style in series:
            if len(x) == 0:
                continue
            if style == "line":
                plt.plot(list(x), list(y), label=label)
            else:  # "scatter" or "scatter:M" with a marker character M (tells series apart without colour)
                marker = style.split(":", 1)[1] if ":" in style else "dot"
                plt.scatter(list(x), list(y), label=label, marker=marker)
            n += len(x)
            names.append(label)
        self.drawn_xlim = None
        if xlim is not None and n:
            xs = [float(v) for _, x, _, _ in series for v in x]
            lo, hi = min(xlim[0], *xs), max(xlim[1], *xs)
            if hi > lo:
                pad = 0.02 * (hi - lo)  # the end targets' markers off the frame
                plt.xlim(lo - pad, hi + pad)
                self.drawn_xlim = (lo - pad, hi + pad)
        self.drawn_points = n
        self.drawn_series = names
        self.refresh()


# -- small terminals ------------------------------------------------------------------------------

def wrap_items(items: Sequence[str], width: int, sep: str = "   ") -> str:
    """`items` (Rich markup) joined by `sep`, broken into lines of at most `width` cells between
    items, never inside one (an item wider than `width` gets a line of its own)."""
    from rich.text import Text

    lines: list[list[str]] = [[]]
    used = 0
    gap = len(sep)
    for item in items:
        n = Text.from_markup(item).cell_len
        if lines[-1] and used + gap + n > width:
            lines.append([])
            used = 0
        used += n + (gap if lines[-1] else 0)
        lines[-1].append(item)
    return "\n".join(sep.join(line) for line in lines)


def set_columns(table, labels: Sequence[str]) -> bool:
    """Give the DataTable `table` the columns `labels` (e.g. shorter ones on a narrow terminal);
    its rows go with the old columns. False (nothing done) when it has them already."""
    if [str(c.label) for c in table.columns.values()] == list(labels):
        return False
    table.clear(columns=True)
    table.add_columns(*labels)
    return True


def columns_fit(table, labels: Sequence[str], rows: Sequence[Sequence[str]], width: int) -> bool:
    """Whether the DataTable `table`'s columns `labels`, with the cells of `rows` (Rich markup,
    in the same order), fit in `width` cells."""
    from rich.text import Text

    pad = 2 * table.cell_padding
    return sum(max([Text.from_markup(label).cell_len, *(Text.from_markup(str(row[i])).cell_len for row in rows)]) + pad
               for i, label in enumerate(labels)) <= width


def fit_columns(table, variants: Sequence[tuple[Sequence[str], Sequence[int] | None]],
                rows: Sequence[Sequence[str]], width: int) -> list[int]:
    """Give the DataTable `table` the columns of the first of `variants` whose columns, with the
    cells of `rows` (Rich markup), fit in `width` cells; else of the last one (the table then
    scrolls sideways). A variant is (labels, order): `order` the indices of the row's cells
    shown, left to right (None: all, as they come), so a narrow terminal can have shorter labels
    and the columns that matter most first. Returns the order chosen: the caller adds each row
    as `[cells[i] for i in order]`."""
    n_cells = len(variants[0][0])
    chosen = None
    for labels, order in variants:
        order = list(range(n_cells)) if order is None else list(order)
        chosen = labels, order
        if columns_fit(table, labels, [[row[i] for i in order] for row in rows], width):
            break
    labels, order = chosen
    set_columns(table, labels)
    return order


# -- choosing a session file -------------------------------------------------------------------

import os  # noqa: E402
from pathlib import Path  # noqa: E402

from textual.app import ComposeResult  # noqa: E402
from textual.containers import Horizontal  # noqa: E402
from textual.message import Message  # noqa: E402
from textual.widgets import Button, Input, Select  # noqa: E402


def known_sessions(folders) -> list[Path]:
    """Session files (*.h5) in `folders`, newest first (at most 50)."""
    found: dict[Path, float] = {}
    for folder in folders:
        if folder is None:
            continue
        folder = Path(folder)
        if folder.is_dir():
            for p in folder.glob("*.h5"):
                try:
                    found[p] = p.stat().st_mtime
                except OSError:
                    continue
    return sorted(found, key=lambda p: -found[p])[:50]


class SessionPicker(Horizontal):
    """A list of known recordings plus a path field; posts `Chosen(path)` on Open."""

    class Chosen(Message):
        def __init__(self, picker: "SessionPicker", path: Path) -> None:
            super().__init__()
            self.picker = picker
            self.path = path

    DEFAULT_CSS = """
    SessionPicker { height: auto; }
    SessionPicker Select { width: 2fr; }
    SessionPicker Input { width: 2fr; }
    SessionPicker Button { width: auto; min-width: 10; }
    """

    def __init__(self, folders_fn, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.folders_fn = folders_fn

    def compose(self) -> ComposeResult:
        yield Select([], prompt="recent sessions", id="session-list", compact=True)
        yield Input(placeholder="or a path: FILE.h5", id="session-path", compact=True)
        yield Button("Open", id="session-open", compact=True, variant="primary")

    def on_mount(self) -> None:
        self.rescan()

    def rescan(self) -> None:
        files = known_sessions(self.folders_fn())
        select = self.query_one("#session-list", Select)
        select.set_options([(str(p), str(p)) for p in files])

    def set_path(self, path: Path) -> None:
        self.query_one("#session-path", Input).value = str(path)

    def on_select_changed(self, event: Select.Changed) -> None:
        event.stop()
        # Nothing chosen (a rescan resets the list) leaves the path field as it is. Textual 8's
        # "no selection" is Select.NULL; Select.BLANK is False and never equals it.
        if event.value is not Select.NULL:
            self.set_path(Path(str(event.value)))

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.choose()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "session-open":
            event.stop()
            self.choose()

    def choose(self) -> None:
        """Open what the path field names (Enter in it, the Open button, ctrl+o on the page)."""
        text = self.query_one("#session-path", Input).value.strip()
        if not text:
            self.app.notify("Choose a recent session or type the path of a session file (.h5).", severity="warning")
            return
        self.post_message(self.Chosen(self, Path(text).expanduser()))


def sample_folders() -> list[Path]:
    """Where sample sessions live: recordings/ in the working folder and in the station's
    source checkout (an editable install), whichever exist."""
    import station

    out = []
    for folder in (Path("recordings"), Path(station.__file__).resolve().parents[1] / "recordings"):
        if folder.is_dir() and all(folder.resolve() != o.resolve() for o in out):
            out.append(folder)
    return out


def output_folder(recording: Path, recordings_dir) -> Path:
    """Where the UI writes what it makes of `recording` (a model, a report, a CSV, a platform
    folder): beside it, unless it is a sample session (recordings/, tracked by git: never written
    into) or its folder cannot be written; then the config's recordings folder (runs/)."""
    folder = Path(recording).parent
    samples = {f.resolve() for f in sample_folders()}
    if folder.resolve() in samples or not os.access(folder, os.W_OK):
        Path(recordings_dir).mkdir(parents=True, exist_ok=True)  # runs/ on a fresh clone
        return Path(recordings_dir)
    return folder
