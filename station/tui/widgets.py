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

    def on_mount(self) -> None:
        super().on_mount()
        self.show([])

    def show(self, series: Sequence[tuple[str, Sequence[float], Sequence[float], str]], title: str | None = None) -> None:
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
            else:
                plt.scatter(list(x), list(y), label=label, marker="dot")
            n += len(x)
            names.append(label)
        self.drawn_points = n
        self.drawn_series = names
        self.refresh()
