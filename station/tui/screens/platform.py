"""Platform screen: what the leg errors, and their compensation, do to the platform pose — the
seed paper's Table 2, as `station platform` computes it.

The input is the analysis on show (the session and the model fitted on Results), or a table
(TABLE.csv from `station table` / Compensation) or a model file typed in, with its recording.
Both measurements of the leg error (the recording's systematic error and one recorded pass) run on
the same poses in a thread worker through procedures.platform.experiment.run_measurements, the
function the CLI uses; `w` writes the CLI's report (station.services.platform_jobs.write_report)
beside the session, in platform/<session name>/.
"""

from __future__ import annotations

from pathlib import Path

from textual import work
from rich.markup import escape
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, VerticalScroll
from textual.message import Message
from textual.widgets import Button, DataTable, Input, Label, Static

from procedures.vocabulary import InputError
from station import values
from station.services.platform_jobs import COMPONENTS, PlatformRequest, PlatformRun, prepare_platform, \
    write_platform_report
from station.tui.error_text import describe
from station.tui.fields import FIELD_KINDS, ValueField
from station.tui.screens.common import FieldRefusal, StationScreen
from station.tui.widgets import XYPlot, columns_fit, set_columns

DEFAULT_POSES = 2000
DEFAULT_SEED = 0
COMPONENT_LABELS = {"x_um": "x", "y_um": "y", "z_um": "z", "rx_rad": "rx", "ry_rad": "ry", "rz_rad": "rz"}
SHORT_MEASUREMENT = {"mean": "systematic", "pass": "one pass"}


def report_folder(recording: Path, recordings_dir) -> Path:
    """Where `w` writes: platform/<session name>/ beside the recording, so reports of several
    sessions in one folder do not overwrite each other; a sample session's under the recordings
    folder instead (widgets.output_folder: never into the tracked recordings/)."""
    from station.tui.widgets import output_folder

    return output_folder(recording, recordings_dir) / "platform" / recording.stem


class PlatformReady(Message):
    def __init__(self, run: PlatformRun) -> None:
        super().__init__()
        self.run = run


class PlatformFailed(Message):
    def __init__(self, error: str, title: str = "Platform") -> None:
        super().__init__()
        self.error = error
        self.title = title


class PlatformWritten(Message):
    def __init__(self, run: PlatformRun, paths: list[Path]) -> None:
        super().__init__()
        self.run = run
        self.paths = paths


# Table 2 on a narrow terminal: shorter labels for its measures and components.
NARROW_MEASURES = {
    "Maximum original error": "Max original", "Minimum original error": "Min original",
    "Maximum compensated error": "Max compensated", "Minimum compensated error": "Min compensated",
    "Range reduction (%)": "Range reduction", "Mean of original abs(error)": "Mean |original|",
    "Mean of compensated abs(error)": "Mean |compensated|",
}
POSE_COLUMNS = ("Measure", "x (µm)", "y (µm)", "z (µm)", "rx (arcsec)", "ry (arcsec)", "rz (arcsec)")
NARROW_POSE_COLUMNS = ("Measure", "x µm", "y µm", "z µm", "rx ″", "ry ″", "rz ″")


def basis_words(inputs: dict) -> str:
    """Which error of the recording the run used (station.services.platform_jobs: the compensation's basis,
    as `station platform` prints it in its first lines), for the status line."""
    basis = (inputs.get("error_basis") or {}).get("basis")
    return {"normalised": "; error normalised to 20 °C", "raw": "; raw error (not normalised to 20 °C)"}.get(basis, "")


def _pct(value) -> str:
    return "n/a" if value is None else f"{value:.2f} %"


class PlatformScreen(StationScreen):
    MODE = "platform"
    PAGE_HELP = ("pose errors of the platform from the leg errors, before and after compensation "
                 "(the paper's Table 2; station platform)")
    AUTO_FOCUS = "#plat-legs"  # arrows choose the plotted component; letter keys act at once
    BINDINGS = [
        Binding("p", "run", "Run"),
        Binding("w", "write_report", "Write report"),
        Binding("c", "next_component", "Component"),
    ]

    def compose(self) -> ComposeResult:
        yield from self.compose_header()
        with VerticalScroll(id="plat-body"):  # on a short terminal the histograms are below, a scroll away
            with Horizontal(classes="controls", id="plat-inputs"):
                yield Label("Compensation ")
                # placeholders short enough for the field at 80 columns; the tooltips say the rest
                yield Input(placeholder="TABLE.csv or MODEL.json", id="plat-comp", compact=True,
                            tooltip="a compensation table (TABLE.csv) or a model (MODEL.json); empty: the model on "
                                    "Results (F3)")
                yield Label(" Recording ")
                yield Input(placeholder="FILE.h5 (empty: on F3)", id="plat-recording", compact=True,
                            tooltip="the session (FILE.h5) the table or model was made from; empty: the session on "
                                    "Results (F3)")
            with Horizontal(classes="controls", id="plat-controls"):
                yield Label("Poses ")
                yield ValueField(str(DEFAULT_POSES), id="plat-poses", kind=FIELD_KINDS["plat-poses"][0], where="poses",
                                 blank=DEFAULT_POSES, compact=True,
                                 tooltip=f"random poses (blank: {DEFAULT_POSES}), as station platform --poses")
                yield Label(" Seed ")
                yield ValueField(str(DEFAULT_SEED), id="plat-seed", kind=values.SEED, where="seed",
                                 blank=DEFAULT_SEED, compact=True,
                                 tooltip=f"random seed (blank: {DEFAULT_SEED}), as station platform --seed")
                yield Button("Run (p)", id="plat-run", compact=True, variant="success")
                yield Button("Write report (w)", id="plat-write", compact=True)
            yield FieldRefusal("plat-poses", "plat-seed", id="plat-refusal")
            yield Static("", id="plat-status", classes="status")
            yield DataTable(id="plat-table", cursor_type="none", zebra_stripes=True)
            yield DataTable(id="plat-legs", cursor_type="row", zebra_stripes=True)
            with Horizontal(id="plat-plots"):  # two panels on the same bins, each with its own count axis
                yield XYPlot("original error", "error", "poses", id="plat-plot-orig")
                yield XYPlot("compensated error", "error", "poses", id="plat-plot-comp")
        yield from self.compose_footer()

    def on_mount(self) -> None:
        self.platform_run: PlatformRun | None = None
        self.component = COMPONENTS[0]
        self.running = False
        self._show()

    def size_changed(self) -> None:
        self._show()  # the tables' labels for the width

    def on_screen_resume(self) -> None:
        if self.platform_run is None:
            self._show_status()

    # -- running ------------------------------------------------------------------------------------
    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "plat-run":
            event.stop()
            self.action_run()
        elif event.button.id == "plat-write":
            event.stop()
            self.action_write_report()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.action_run()

    def _number(self, widget_id: str) -> int | None:
        """The value of the ValueField `widget_id` (its kind's parser, the command line's), or None
        after saying (in a notification; under the fields too) what is wrong and what to type."""
        try:
            return self.query_one(widget_id, ValueField).read()
        except InputError as exc:
            self.notify(escape(f"{exc}; nothing run"), title="Platform", severity="error", timeout=10)
            return None

    def _request(self) -> PlatformRequest | None:
        """The run the fields ask for, or None (after saying what is missing)."""
        poses = self._number("#plat-poses")
        seed = self._number("#plat-seed")
        if poses is None or seed is None:
            return None
        comp_text = self.query_one("#plat-comp", Input).value.strip()
        rec_text = self.query_one("#plat-recording", Input).value.strip()
        recording = Path(rec_text).expanduser() if rec_text else None
        a = self.app.analysis
        if not comp_text:
            if a is None:
                self.notify("No model on show: open a session of six legs on Results (F3) and fit it, or type a "
                            "compensation table (TABLE.csv) and its recording here.", title="Platform",
                            severity="warning", timeout=10)
                return None
            return PlatformRequest(poses, seed, analysis=a, recording=recording)
        comp = Path(comp_text).expanduser()
        suffix = comp.suffix.lower()
        if suffix not in (".csv", ".json"):
            self.notify(f"{comp.name}: give a compensation table (TABLE.csv, from Compensation F4 or station table) "
                        "or a model (MODEL.json, from Results F3 or station fit).", title="Platform",
                        severity="error", timeout=10)
            return None
        if suffix == ".csv" and recording is None:
            recording = a.path if a is not None else self.app.last_session
            if recording is None:
                self.notify(f"{comp.name} does not name its recording: type the session (FILE.h5) the table was "
                            "made from under Recording.", title="Platform", severity="warning", timeout=10)
                return None
        return PlatformRequest(poses, seed, source=comp, recording=recording)

    def action_run(self) -> None:
        if self.running:
            self.notify("The platform experiment is running already.", severity="warning", timeout=4)
            return
        request = self._request()
        if request is None:
            return
        self.running = True
        self.query_one("#plat-status", Static).update(
            f"running {request.poses} poses (seed {request.seed}), both measurements…")
        self._run_worker(request)

    @work(thread=True, exclusive=True, group="platform", exit_on_error=False)
    def _run_worker(self, request: PlatformRequest) -> None:
        try:
            run = self.app.jobs.run(prepare_platform(request)).data  # the app's one JobRunner
        except Exception as exc:
            self.post_message(PlatformFailed(describe(exc, "cannot run the platform experiment")))
            return
        self.post_message(PlatformReady(run))

    def on_platform_ready(self, message: PlatformReady) -> None:
        self.running = False
        self.platform_run = message.run
        self._show()

    def on_platform_failed(self, message: PlatformFailed) -> None:
        self.running = False
        self._show_status()
        self.notify(message.error, title=message.title, severity="error", timeout=15)

    # -- writing --------------------------------------------------------------------------------------
    def action_write_report(self) -> None:
        if self.platform_run is None:
            self.notify("Run the experiment first (p).", title="Platform", severity="warning")
            return
        self._write_worker(self.platform_run, report_folder(self.platform_run.recording, self.app.cfg.recordings_dir))

    @work(thread=True, exclusive=True, group="platform-write", exit_on_error=False)
    def _write_worker(self, run: PlatformRun, out: Path) -> None:
        try:
            paths = write_platform_report(run, out)
        except Exception as exc:
            self.post_message(PlatformFailed(describe(exc, f"cannot write the platform report to {out}"),
                                             title="Platform report"))
            return
        self.post_message(PlatformWritten(run, paths))

    def on_platform_written(self, message: PlatformWritten) -> None:
        message.run.written = message.paths
        folder = message.paths[0].parent
        where = f"platform/{folder.name}/" if self.app.hide_volatile else str(folder)
        self.notify(f"Platform report written to {where}: " + ", ".join(p.name for p in message.paths),
                    title="Platform report", timeout=8)
        if message.run is self.platform_run:
            self._show_status()

    # -- component of the plot ------------------------------------------------------------------------
    def action_next_component(self) -> None:
        self.component = COMPONENTS[(COMPONENTS.index(self.component) + 1) % len(COMPONENTS)]
        table = self.query_one("#plat-legs", DataTable)
        if table.row_count == len(COMPONENTS):
            table.move_cursor(row=COMPONENTS.index(self.component))
        self._show_plot()

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        key = event.row_key.value if event.row_key is not None else None
        if key in COMPONENTS and key != self.component:
            self.component = key
            self._show_plot()

    # -- drawing ----------------------------------------------------------------------------------------
    def _show_status(self) -> None:
        status = self.query_one("#plat-status", Static)
        run = self.platform_run
        if run is None:
            a = self.app.analysis
            if a is None:
                status.update("no analysis on show: fit a six-leg session on Results (F3), or type a table and its "
                              "recording; then p")
            else:  # "press p" only for what p accepts: the errors of all six legs
                legs = [int(leg) for leg in a.session.legs]
                missing = [leg for leg in range(1, 7) if leg not in legs]
                if missing:
                    status.update(f"the {a.method} model on show ([b]{a.path.name}[/b]) has leg(s) {legs}, no "
                                  f"{missing}: the platform needs all six legs. Fit a session of legs 1-6 on "
                                  "Results (F3), or type a table and its recording above; then p")
                else:
                    status.update(f"ready: the {a.method} model fitted on [b]{a.path.name}[/b] "
                                  f"(legs {legs}); press p to run")
            return
        s = run.summary
        other = s.get("other_measurement")
        lines = [f"[b]{run.label}[/b]: {s['poses_used']} of {s['poses']} poses used, seed {s['seed']}{basis_words(run.inputs)}"
                 + (f"   [dim]report in platform/{run.recording.stem}/[/dim]" if run.written else "")]
        counts = []
        for measured, acc in [(s.get("measured"), s["acceptance"])] + ([(other["measured"], other["acceptance"])] if other else []):
            n_ok = sum(1 for v in acc.values() if v["at_least_leg_reduction"])
            counts.append(f"{SHORT_MEASUREMENT.get(measured or '', 'pose')} {n_ok}/{len(acc)}")
        lines.append(f"Table 2: {run.measurement_label(s.get('measured'))}. "
                     f"At least as much as the legs: {', '.join(counts)}")
        status.update("\n".join(lines))

    def _show(self) -> None:
        table = self.query_one("#plat-table", DataTable)
        legs = self.query_one("#plat-legs", DataTable)
        table.clear()
        legs.clear(columns=True)
        self._show_status()
        run = self.platform_run
        width = self.app.size.width - 4  # the body's padding, its scroll bar
        if run is None:
            set_columns(table, POSE_COLUMNS if columns_fit(table, POSE_COLUMNS, [], width) else NARROW_POSE_COLUMNS)
            legs.add_columns("Component", "Pose range reduction", "Legs (pooled)", "At least as much", "Dominant leg")
            self._show_plot()
            return
        s = run.summary
        rows = [(label, *cells) for label, cells in run.pose_rows()]
        if columns_fit(table, POSE_COLUMNS, rows, width):
            set_columns(table, POSE_COLUMNS)
        else:  # a narrow terminal: the short labels
            set_columns(table, NARROW_POSE_COLUMNS)
            rows = [(NARROW_MEASURES.get(row[0], row[0]), *row[1:]) for row in rows]
        for row in rows:
            table.add_row(*row)
        columns = [(s.get("measured"), s["acceptance"], s["legs"]["all"]["range_reduction_pct"])]
        other = s.get("other_measurement")
        if other:
            columns.append((other["measured"], other["acceptance"], other["leg_range_reduction_pct"]))
        heads = ["Component"]
        for measured, _, _ in columns:
            name = SHORT_MEASUREMENT.get(measured or "", "pose")
            heads += [f"{name}: pose", "legs", "≥ legs"]
        heads += ["dominant leg before", "after"]
        legs.add_columns(*heads)
        for k, comp in enumerate(COMPONENTS):
            cells = [COMPONENT_LABELS[comp]]
            for _, acc, leg_red in columns:
                a = acc[comp]
                cells += [_pct(a["range_reduction_pct"]), _pct(leg_red), "yes" if a["at_least_leg_reduction"] else "no"]
            cells += [run.dominant("original", k), run.dominant("compensated", k)]
            legs.add_row(*cells, key=comp)
        legs.move_cursor(row=COMPONENTS.index(self.component))
        self._show_plot()

    def _show_plot(self) -> None:
        plots = self.query_one("#plat-plot-orig", XYPlot), self.query_one("#plat-plot-comp", XYPlot)
        run = self.platform_run
        if run is None:
            for plot, what in zip(plots, ("original", "compensated")):
                plot.show([], title=f"{what} pose error (no run yet)")
            return
        name = COMPONENT_LABELS[self.component]
        xs, c0, c1, unit = run.histogram(self.component)
        measured = SHORT_MEASUREMENT.get(run.summary.get("measured") or "", "")
        for plot, what, counts in zip(plots, ("original", "compensated"), (c0, c1)):
            plot.xlabel_text = f"{name} error ({unit})"
            plot.show([(what, xs, counts, "line")],
                      title=f"{name}: {what} error, {measured} measurement" + ("" if what == "original" else " (c: next)"))
