"""History page (F8): a leg's history by serial number, from the catalog (station/catalog), as
`station history SERIAL` prints it: every calibration with its ISO 230-2 values E, B, M and their
U, tables pushed and to which drive, verifications; a plot of E and B over time, and the due
date. Read in a thread worker: a shared catalog that does not answer costs its connect timeout,
never a frozen screen."""

from __future__ import annotations

from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, VerticalScroll
from textual.message import Message
from textual.widgets import Button, DataTable, Input, Label, Static

from station.catalog.history import History, history, parse_utc, row_detail, value_with_u
from station.catalog.store import catalog_of, reading_engine
from station.tui.error_text import describe
from station.tui.screens.common import StationScreen
from station.tui.widgets import XYPlot

COLUMNS = ("time (UTC)", "kind", "station", "outcome", "E um", "B um", "M um", "detail")


class HistoryLoaded(Message):
    def __init__(self, result: History | None, where: str, error: str = "") -> None:
        super().__init__()
        self.result = result
        self.where = where
        self.error = error


class HistoryScreen(StationScreen):
    MODE = "history"
    PAGE_HELP = "a leg's calibrations, tables and verifications by serial number, from the catalog (station history)"
    AUTO_FOCUS = "#hist-load"  # as on every page: a letter key acts, the serial is one click or Tab away
    BINDINGS = [Binding("l", "load", "Load")]

    def compose(self) -> ComposeResult:
        yield from self.compose_header()
        with VerticalScroll(id="hist-body"):
            with Horizontal(classes="controls"):
                yield Label("Serial ")
                yield Input(placeholder="e.g. HX-0042", id="hist-serial", compact=True)
                yield Button("Load (l)", id="hist-load", compact=True, variant="success")
            yield Static("", id="hist-status", classes="status")
            yield DataTable(id="hist-table", cursor_type="row", zebra_stripes=True)
            yield XYPlot("E and B over time", "days since the first calibration", "um", id="hist-plot")
        yield from self.compose_footer()

    def on_mount(self) -> None:
        super().on_mount()
        self.history: History | None = None
        self.query_one("#hist-table", DataTable).add_columns(*COLUMNS)

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.action_load()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "hist-load":
            event.stop()
            self.action_load()

    def action_load(self) -> None:
        serial = self.query_one("#hist-serial", Input).value.strip()
        if not serial:
            self.query_one("#hist-status", Static).update("type a leg's serial number, then Enter")
            return
        self.query_one("#hist-status", Static).update(f"reading the catalog for {serial} ...")
        self._read(serial)

    @work(thread=True, exclusive=True)
    def _read(self, serial: str) -> None:
        cfg = self.app.cfg
        try:
            engine, where = reading_engine(catalog_of(cfg))
            result = history(engine, serial, cfg.catalog.calibration_interval_days)
        except Exception as exc:  # one line on the page, never a traceback
            self.post_message(HistoryLoaded(None, "", describe(exc, "reading the catalog")))
            return
        self.post_message(HistoryLoaded(result, where))

    def on_history_loaded(self, message: HistoryLoaded) -> None:
        status = self.query_one("#hist-status", Static)
        table = self.query_one("#hist-table", DataTable)
        table.clear()
        if message.result is None:
            status.update(f"[red]{message.error}[/red]")
            return
        h = self.history = message.result
        for r in h.rows:
            detail = row_detail(r)
            table.add_row(r.time_utc[:19], r.kind, r.station_id or "-", r.outcome or "-", value_with_u(r.figures, "E"),
                          value_with_u(r.figures, "B"), value_with_u(r.figures, "M"),
                          detail.rsplit("/", 1)[-1] if r.kind not in ("push", "rollback") else detail)
        if not h.rows:
            status.update(f"{message.where}: no records of a leg with serial {h.serial!r}")
        else:
            due = f"; due {h.due}" if h.due else "; never calibrated"
            drift = ""
            if h.drift and h.drift[-1].um_per_month.get("E") is not None:
                drift = f"; E drift {h.drift[-1].um_per_month['E']:+.3f} um/month since the calibration before"
            status.update(f"{message.where}: {len(h.rows)} record(s), {len(h.calibrations)} calibration(s){due}{drift}")
        cals = h.calibrations
        series = []
        if cals:
            t0 = parse_utc(cals[0].time_utc)
            days = [(parse_utc(r.time_utc) - t0).total_seconds() / 86400.0 for r in cals]
            for name in ("E", "B"):
                pts = [(d, (r.figures.get(name) or {}).get("value_um")) for d, r in zip(days, cals)]
                pts = [(d, v) for d, v in pts if v is not None]
                series.append((name, [d for d, _ in pts], [v for _, v in pts], "line"))
        self.query_one("#hist-plot", XYPlot).show(series)
