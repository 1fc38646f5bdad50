"""Results screen: ISO 230-2 figures per leg, the fitted model over the measured points, the
residual, and the held-out residual against the noise floor; method default or paper.

Reading, fitting and evaluating run in a thread worker; the result is kept on the app
(`app.analysis`) for the Compensation screen. A damaged session file is refused by the reader
within seconds, in the worker, and said in a notification.

`r` writes the report of `station report` and `e` the CSV of `station export` for the session
on show, through the same functions (station.services.report_jobs, procedures.io.csv_io.export_csv), beside
the recording: report/<session>.<method>/ and <session>.csv. Neither replaces what is there.

The error is the one `station fit` and `station iso230` use, chosen by the same function
(procedures.metrology.thermal.error_basis): normalised to 20 degC material temperature by
default, raw after `t` (their `--raw`); the status says which in one line (the commands' lines
in its tooltip), and the model carries it (`error_basis`) for the table made from it on the Compensation page.

The status says what the table shows; a failed fit's error line belongs to the method it was
asked for and goes when another method is chosen. An answer of a fit asked for before the last
request (another file, another method) is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, VerticalScroll
from textual.message import Message
from textual.widgets import Button, DataTable, Label, Select, Static

from station.tui.error_text import describe
from station.tui.screens.common import StationScreen
from station.tui.widgets import SessionPicker, XYPlot, fit_columns, output_folder

NO_SESSION = "no session open: finish a sweep, or open a session file above"
# The table's columns (µm throughout; "held-out" = RMS of the residual on cycles the fit did not
# see) as (labels, order of the cells): the first that fits the terminal is shown; a narrow one
# has shorter labels and the ISO 230-2 figures beside the leg (points and cycles last).
COLUMNS = [
    (("Leg", "Points", "Cycles", "Noise floor", "Held-out RMS", "Held-out ratio", "Range before → held-out range",
      "A", "E", "M", "B", "R"), None),
    (("Leg", "Points", "Cycles", "Noise floor", "Held-out RMS", "Ratio", "Range → held-out",
      "A", "E", "M", "B", "R"), None),
    # 80 columns: the range before → held-out range on two lines (cell 12), beside the ISO figures,
    # so it is whole on screen with the held-out RMS, noise floor and ratio (points, cycles: a
    # sideways scroll away)
    (("Leg", "A", "E", "M", "B", "R", "Range→HO", "HO RMS", "Noise", "Ratio", "Points", "Cycles"),
     (0, 7, 8, 9, 10, 11, 12, 4, 3, 5, 1, 2)),
]
METHODS = [("default (bidirectional, cross-validated)", "default"), ("paper (Fourier, Algorithm 1)", "paper")]


@dataclass
class Analysis:
    """A recording with its fitted model and ISO 230-2 evaluation (None when unavailable)."""

    path: Path
    session: Any  # procedures.io.recording.reader.Session
    method: str
    model: Any  # procedures.fit.LegErrorModel
    iso: Any = None
    iso_note: str = ""
    model_path: Path | None = None
    iso_u: dict[int, dict[str, float | None]] | None = None  # leg -> value name -> U (k = 2), um
    raw: bool = False  # the raw error (`--raw`), else normalised to 20 degC
    points: Any = None  # the points analysed: session.points with error_um on the chosen basis
    basis_lines: tuple[str, ...] = ()  # what error_basis says, as the commands print it
    basis: dict | None = None  # the same as JSON (the model's options["error_basis"])
    decisions: dict | None = None  # procedures.reporting.decision per leg when the session states tolerances
    decision_summary: str = ""  # the decisions in one line (station.services.analysis.analyse_file)

    @property
    def analysed_points(self) -> Any:
        return self.session.points if self.points is None else self.points


class AnalysisReady(Message):
    def __init__(self, analysis: Analysis, request: int = 0) -> None:
        super().__init__()
        self.analysis = analysis
        self.request = request  # the fit request it answers (ResultsScreen._request)


class AnalysisFailed(Message):
    def __init__(self, error: str, method: str = "", request: int = 0, raw: bool = False) -> None:
        super().__init__()
        self.error = error
        self.method = method
        self.request = request
        self.raw = raw


class FilesWritten(Message):
    """A report or CSV written (`error` empty) or refused, from the writing worker."""

    def __init__(self, title: str, text: str, error: str = "") -> None:
        super().__init__()
        self.title = title
        self.text = text
        self.error = error


def report_folder(recording: Path, method: str, recordings_dir) -> Path:
    """Where `r` writes: report/<session name>.<method>/ beside the recording (the `--out` of
    `station report`), so reports of several sessions and methods do not overwrite each other;
    a sample session's under the recordings folder instead (widgets.output_folder)."""
    return output_folder(recording, recordings_dir) / "report" / f"{recording.stem}.{method}"


def csv_path(recording: Path, recordings_dir) -> Path:
    """Where `e` writes: <session name>.csv beside the recording (the `--out` of `station export`);
    a sample session's in the recordings folder (widgets.output_folder)."""
    return output_folder(recording, recordings_dir) / f"{recording.stem}.csv"


def iso_figures(iso: Any, leg: int) -> dict[str, float | None]:
    """A, E, M, B, R (um, both directions) of one leg from procedures.reporting.iso230.evaluate's result;
    a value the standard's definitions cannot give from this data is None (shown as n/a)."""
    if not iso or leg not in iso:
        return {}
    values = iso[leg].values
    return {k: values.get(k) for k in "AEMBR"}


def basis_name(raw: bool) -> str:
    return "raw" if raw else "20 °C"


def basis_text(lines: tuple[str, ...] | list[str], basis: dict | None, raw: bool) -> str:
    """The error basis in one line for the status (the page must fit 80x24): the head of what
    procedures.metrology.thermal.error_basis says (as `station fit` and `station iso230` print it)
    with the material temperature and correction ranges over the normalised legs, and the key to
    switch. The commands' full lines are the status' tooltip."""
    from rich.markup import escape

    if not lines:
        return f"error: {basis_name(raw)}"
    if raw or not basis or not basis.get("normalised"):
        head = lines[0].replace(" (--raw)", "")
        return escape(head) + f"  [dim](t: {'normalise to 20 °C' if raw else 'raw'})[/dim]"
    from station.services.analysis import normalised_basis_text

    text = normalised_basis_text(basis)
    return escape(text) + "  [dim](t: raw)[/dim]"


def _fmt(value: float | None, spec: str = ".3f") -> str:
    return "n/a" if value is None else format(value, spec)


def _with_u(value: float | None, u: float | None) -> str:
    """An ISO value over its expanded uncertainty, two lines: "3.924" / "±1.191"."""
    if value is None:
        return "n/a"
    return f"{value:.3f}" if u is None else f"{value:.3f}\n±{u:.3f}"


def _widest_line(cell: str) -> str:
    return max(cell.split("\n"), key=len)


class ResultsScreen(StationScreen):
    MODE = "results"
    PAGE_HELP = "ISO 230-2 per leg, model over the measured points, residual; held-out RMS against the noise floor"
    BINDINGS = [
        Binding("ctrl+o", "open_session", "Open", key_display="^o"),
        Binding("f", "fit", "Fit"),
        Binding("m", "toggle_method", "Method"),
        # short in the footer (two rows at 80 columns), the help gives the tooltip's words
        Binding("t", "toggle_basis", "Raw/20 °C", tooltip="Error raw / normalised to 20 °C (--raw)"),
        Binding("l", "next_leg", "Next leg"),
        Binding("w", "save_model", "Save model"),
        Binding("r", "write_report", "Report"),
        Binding("e", "export_csv", "Export CSV"),
    ]

    def compose(self) -> ComposeResult:
        yield from self.compose_header()
        with VerticalScroll(id="results-body"):  # ISO 230-2 caveats can push the plots below, a scroll away
            yield SessionPicker(self._folders, id="results-picker")
            with Horizontal(id="results-controls"):
                yield Label("Method ")
                yield Select(METHODS, value="default", allow_blank=False, id="method", compact=True)
                yield Button("Fit (f)", id="fit", compact=True, variant="success")
                yield Button("Save model (w)", id="save-model", compact=True)
                yield Button("Report (r)", id="write-report", compact=True)
                yield Button("CSV (e)", id="export-csv", compact=True)
            yield Static(NO_SESSION, id="results-status")
            yield DataTable(id="results-table", cursor_type="row", zebra_stripes=True)
            with Horizontal(id="results-plots"):
                yield XYPlot("measured and model", "position mm", "error µm", id="model-plot")
                yield XYPlot("residual = error − model", "position mm", "µm", id="residual-plot")
        yield from self.compose_footer()

    def _folders(self):
        from station.tui.widgets import sample_folders

        return [self.app.cfg.recordings_dir, *sample_folders()]

    def on_mount(self) -> None:
        self.plot_leg: int | None = None
        self._request = 0  # numbers the fit requests: only the newest one's answer is shown
        self._fitting: tuple[Path, str, bool] | None = None  # (path, method, raw) of the fit under way
        self.failure: tuple[str, str] | None = None  # (method, error) of the last failed fit
        self.raw = False  # the error basis asked for: False = normalised to 20 degC (the commands' default)
        self._show()
        self.follow_sessions()  # after _show: it may start opening the newest session

    def _on_new_session(self, path) -> None:
        """A new recording (a sweep ended, a session opened on another page) is offered, and
        opened when no session is open here: F3 after a sweep shows that session, not "no session
        open" with its path filled in. One on show stays (the Compensation page works on it)."""
        super()._on_new_session(path)
        if self.app.analysis is None and self._fitting is None and Path(path).exists():
            self._start_fit(Path(path), self._method(), self.raw)

    # -- actions -----------------------------------------------------------------------------------
    def on_session_picker_chosen(self, message: SessionPicker.Chosen) -> None:
        # app.last_session follows once the file is read and fitted (on_analysis_ready): a file
        # that cannot be read does not become the session the other pages offer
        self._start_fit(message.path, self._method(), self.raw)

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "fit":
            event.stop()
            self.action_fit()
        elif event.button.id == "save-model":
            event.stop()
            self.action_save_model()
        elif event.button.id == "write-report":
            event.stop()
            self.action_write_report()
        elif event.button.id == "export-csv":
            event.stop()
            self.action_export_csv()

    def action_toggle_method(self) -> None:
        select = self.query_one("#method", Select)
        select.value = "paper" if select.value == "default" else "default"

    def _method(self) -> str:
        value = self.query_one("#method", Select).value
        return "default" if value is Select.NULL else str(value)  # allow_blank=False: never NULL

    def on_select_changed(self, event: Select.Changed) -> None:
        if event.select.id != "method":
            return
        event.stop()
        # Another method: the error of the one before is not this one's, and a fit under way
        # for the one before is not wanted any more.
        self.failure = None
        a = self.app.analysis
        if self._fitting is not None:
            if self._fitting[1] != self._method():  # (not when it is this method's fit already)
                self._start_fit(self._fitting[0], self._method(), self.raw)
        elif a is not None and a.method != self._method():
            self._start_fit(a.path, self._method(), self.raw)
        else:  # the analysis on show is of this method already
            self._show()

    def action_toggle_basis(self) -> None:
        """Raw error (`--raw` of station fit and iso230) or normalised to 20 degC (their default):
        the session on show (or being fitted) is fitted and evaluated again on the other."""
        self.raw = not self.raw
        self.failure = None
        a = self.app.analysis
        if self._fitting is not None:
            self._start_fit(self._fitting[0], self._fitting[1], self.raw)
        elif a is not None and a.raw != self.raw:
            self._start_fit(a.path, self._method(), self.raw)
        else:
            self._show()

    def action_fit(self) -> None:
        text = self.query_one("#session-path").value.strip()
        path = Path(text).expanduser() if text else self.app.last_session
        if path is None:
            self.notify("Open a session first (a finished sweep opens itself here).", severity="warning")
            return
        self._start_fit(Path(path), self._method(), self.raw)

    def _start_fit(self, path: Path, method: str, raw: bool = False) -> None:
        self._request += 1
        self._fitting = (path, method, raw)
        self.failure = None
        self.query_one("#results-status", Static).update(f"reading and fitting ({method}, {basis_name(raw)})…")
        self._analyse(path, method, raw, self._request)

    @work(thread=True, exclusive=True, group="analysis", exit_on_error=False)
    def _analyse(self, path: Path, method: str, raw: bool = False, request: int = 0) -> None:
        try:
            from station.services.analysis import analyse_file

            # the error, model and ISO figures `station fit` and `station iso230` give (normalised to 20 degC unless
            # raw), and the ISO 14253-1 decisions against the recorded [tolerances] (docs/decisions.md)
            done = analyse_file(path, method, raw)
        except Exception as exc:
            self.post_message(AnalysisFailed(describe(exc, f"cannot analyse {path.name}"), method, request, raw))
            return
        a = done.analysis
        note = ""
        if a.iso_error is not None:
            note = describe(a.iso_error, "ISO 230-2")
        elif a.uncertainty_error is not None:  # the values stand without their U; say why
            note = describe(a.uncertainty_error, "ISO 230-2 uncertainty")
        if done.decisions_error is not None:
            note = describe(done.decisions_error, "the tolerance decisions")
        self.post_message(AnalysisReady(Analysis(path, a.session, method, a.model, a.iso, note, iso_u=a.iso_u, raw=raw,
                                                 points=a.points, basis_lines=a.basis_lines, basis=a.basis,
                                                 decisions=done.decisions, decision_summary=done.decision_summary),
                                        request))

    def on_analysis_ready(self, message: AnalysisReady) -> None:
        if message.request != self._request:  # asked for before the last request
            return
        self._fitting = None
        self.raw = message.analysis.raw
        self.app.analysis = message.analysis
        self.app.last_session = message.analysis.path
        self.plot_leg = None
        self._show()

    def on_analysis_failed(self, message: AnalysisFailed) -> None:
        if message.request != self._request:
            return
        self._fitting = None
        self.failure = (message.method, message.error)
        self._show()
        self.notify(message.error, title="Results", severity="error", timeout=12)

    def action_next_leg(self) -> None:
        a = self.app.analysis
        if a is None:
            return
        legs = list(a.model.legs)
        current = self.plot_leg if self.plot_leg in legs else legs[0]
        self.plot_leg = legs[(legs.index(current) + 1) % len(legs)]
        self._show_plots()

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        if event.row_key is not None and event.row_key.value is not None and self.app.analysis is not None:
            leg = int(event.row_key.value)
            if leg != self.plot_leg:
                self.plot_leg = leg
                self._show_plots()

    def action_save_model(self) -> None:
        a = self.app.analysis
        if a is None:
            self.notify("Fit a model first (f).", severity="warning")
            return
        from station.services.analysis import save_session_model

        out = output_folder(a.path, self.app.cfg.recordings_dir) / f"{a.path.stem}.{a.method}.model.json"
        try:
            save_session_model(a.model, out, a.session, self.app.cfg)
        except Exception as exc:
            self.notify(describe(exc, "cannot save the model"), severity="error", timeout=12)
            return
        a.model_path = out
        self.notify(f"Model saved: {out if not self.app.hide_volatile else out.name}", timeout=6)

    # -- report and CSV (station report, station export) ----------------------------------------------
    def _where(self, path: Path) -> str:
        return path.name if self.app.hide_volatile else str(path)

    def action_write_report(self) -> None:
        """`station report SESSION --out report/<session>.<method>/ --model MODEL.json` with the model
        on show (as `station fit` makes it: on the error normalised to 20 degC by default; on the raw
        error, `t`, the default model is the one `station report` without --model fits)."""
        a = self.app.analysis
        if a is None:
            self.notify("Open a session first: the report is of the session and model on show.", title="Report",
                        severity="warning")
            return
        out = report_folder(a.path, a.method, self.app.cfg.recordings_dir)
        if out.exists() and (not out.is_dir() or any(out.iterdir())):
            self.notify(f"{self._where(out)} exists already (a report written before): rename or delete it, "
                        "then press r again.", title="Report", severity="warning", timeout=12)
            return
        self.notify(f"Writing the report of {a.path.name} ({a.method} model)…", title="Report", timeout=4)
        self._report_worker(a.session, a.model, out, self.app.hide_volatile)

    @work(thread=True, group="results-write", exit_on_error=False)
    def _report_worker(self, session, model, out: Path, hide: bool) -> None:
        try:
            from station.services.report_jobs import prepare_session_report

            # the job `station report` runs, through the app's one JobRunner
            done = self.app.jobs.run(prepare_session_report(session, model, out, self.app.cfg))
            result, notes = done.data, [line for line in done.lines if line.startswith("note:")]
        except Exception as exc:
            self.post_message(FilesWritten("Report", "", describe(exc, f"cannot write the report to {out}")))
            return
        where = f"report/{out.name}/" if hide else str(out)
        self.post_message(FilesWritten("Report", f"Report written to {where}: "
                                       + ", ".join(p.name for p in result.files) + "".join("\n" + n for n in notes)))

    def action_export_csv(self) -> None:
        """`station export SESSION --out <session>.csv` (no --force: an existing file is kept)."""
        a = self.app.analysis
        if a is None:
            self.notify("Open a session first: the CSV is of the session on show.", title="Export CSV",
                        severity="warning")
            return
        out = csv_path(a.path, self.app.cfg.recordings_dir)
        if out.exists():
            self.notify(f"{self._where(out)} exists already: rename or delete it, then press e again.",
                        title="Export CSV", severity="warning", timeout=12)
            return
        self._export_worker(a.path, out, self.app.hide_volatile)

    @work(thread=True, group="results-write", exit_on_error=False)
    def _export_worker(self, session_path: Path, out: Path, hide: bool) -> None:
        try:
            from station.services.csv_jobs import ExportRequest, prepare_export

            lines = self.app.jobs.run(prepare_export(ExportRequest(session_path, out, make_parents=True))).lines
        except Exception as exc:
            self.post_message(FilesWritten("Export CSV", "", describe(exc, f"cannot export {session_path.name}")))
            return
        text = "\n".join(lines)
        if hide:
            text = text.replace(str(out), out.name)
        self.post_message(FilesWritten("Export CSV", text))

    def on_files_written(self, message: FilesWritten) -> None:
        if message.error:
            self.notify(message.error, title=message.title, severity="error", timeout=12)
        else:
            self.notify(message.text, title=message.title, timeout=10)

    # -- drawing -----------------------------------------------------------------------------------
    def _failure_text(self, a: Analysis | None) -> str:
        """The error of the last failed fit, if it was of the method now chosen."""
        if self.failure is None or self.failure[0] != self._method():
            return ""
        text = f"[red]{self.failure[1]}[/red]"
        if a is not None:
            text += f"\n[dim]the table shows the {a.method} model of {a.path.name}[/dim]"
        return text

    def size_changed(self) -> None:
        self._show()  # the table's labels for the width

    def _show(self) -> None:
        a = self.app.analysis
        status = self.query_one("#results-status", Static)
        table = self.query_one("#results-table", DataTable)
        table.clear()
        failure = self._failure_text(a)
        if a is None:
            fit_columns(table, COLUMNS, [], self.app.size.width - 2)
            if self._fitting is not None:
                status.update(f"reading and fitting ({self._fitting[1]}, {basis_name(self._fitting[2])})…")
            else:
                status.update(failure or NO_SESSION)
            self._show_plots()
            return
        s = a.session
        name = a.path.name if self.app.hide_volatile else str(a.path)
        text = (f"[b]{name}[/b]  {s.outcome}, {len(s.points)} points, legs {s.legs}   method [b]{a.method}[/b]"
                "   [dim](figures in µm; ISO 230-2 values over ±U, k = 2)[/dim]")
        text += "\n" + basis_text(a.basis_lines, a.basis, a.raw)
        status.tooltip = "\n".join(a.basis_lines) or None
        if self.raw != a.raw:  # asked for the other basis, not fitted yet (press f)
            text += f"\n[yellow]{basis_name(self.raw)} error chosen: press f to fit on it[/yellow]"
        if a.iso_note:
            text += f"\n[yellow]{a.iso_note}[/yellow]"
        if a.decisions:
            text += f"\n[b]{a.decisions['stage'].replace('_', '-')}[/b] (ISO 14253-1): {a.decision_summary}"
        extra = []
        for leg, r in (a.iso or {}).items():
            extra += [f"[yellow]leg {leg}:[/yellow] {note}" for note in r.notes]
            extra += [f"[yellow]leg {leg}: not computed:[/yellow] {why}" for why in sorted(set(r.reasons.values()))]
        if extra:  # ISO 230-2 caveats (too few approaches, a stray run, ...): the first few
            text += "\n" + "\n".join(extra[:3]) + (f"\n… and {len(extra) - 3} more" if len(extra) > 3 else "")
        if failure:
            text = failure + "\n" + text
        status.update(text)
        rows = {}
        for leg, lf in a.model.legs.items():
            st = lf.stats
            iso = iso_figures(a.iso, leg)
            iso_u = (a.iso_u or {}).get(leg, {})
            ratio = st.heldout_ratio
            rows[leg] = (
                str(leg), str(st.n_points), str(st.n_cycles), _fmt(st.noise_floor_um), _fmt(st.heldout_rms_um),
                _fmt(ratio, ".2f") if ratio is not None else "n/a",
                f"{st.range_before_um:.2f} → {_fmt(st.heldout_range_um, '.2f')}",
                *(_with_u(iso.get(k), iso_u.get(k)) for k in "AEMBR"),
                f"{st.range_before_um:.2f} →\n{_fmt(st.heldout_range_um, '.2f')}",  # cell 12: the narrow table's
            )
        # two-line cells (value over ±U): the columns are as wide as their widest line
        widths = [[_widest_line(c) for c in cells] for cells in rows.values()]
        order = fit_columns(table, COLUMNS, widths, self.app.size.width - 2)
        height = 2 if any("\n" in cells[i] for cells in rows.values() for i in order) else 1
        for leg, cells in rows.items():
            table.add_row(*(cells[i] for i in order), key=str(leg), height=height)
        self._show_plots()

    def _show_plots(self) -> None:
        a = self.app.analysis
        mplot = self.query_one("#model-plot", XYPlot)
        rplot = self.query_one("#residual-plot", XYPlot)
        if a is None:
            mplot.show([], title="measured and model (no session)")
            rplot.show([], title="residual (no session)")
            return
        legs = list(a.model.legs)
        leg = self.plot_leg if self.plot_leg in legs else legs[0]
        self.plot_leg = leg
        points = a.analysed_points  # the error the model was fitted to
        pts = points[points["leg"] == leg]
        lf = a.model.leg(leg)
        grid = np.linspace(lf.stroke_mm[0], lf.stroke_mm[1], 200)
        series, resid = [], []
        for d, name in ((1, "+1"), (-1, "−1")):
            p = pts[pts["direction"] == d]
            if len(p) == 0:
                continue
            series.append((f"measured {name}", p["target_mm"], p["error_um"], "scatter" if d > 0 else "scatter:x"))
            series.append((f"model {name}", grid, a.model.predict_um(leg, grid, d), "line"))
            resid.append((f"residual {name}", p["target_mm"],
                          p["error_um"] - a.model.predict_um(leg, p["target_mm"], d), "scatter" if d > 0 else "scatter:x"))
        st = lf.stats
        mplot.show(series, title=f"leg {leg}: measured and {a.method} model")
        rplot.show(resid, title=f"leg {leg}: residual (in-sample); held-out RMS {_fmt(st.heldout_rms_um)} µm, "
                                f"noise floor {_fmt(st.noise_floor_um)} µm")
