"""Diagnosis screen: the gap between the digital twin and a recording — where it lies, which
unmodelled effect explains it, how far it shrinks — with a per-leg plot of the gap along the
stroke. The diagnosis is procedures.diagnosis.diagnose (the same as `station diagnose`), run in a
thread worker, which also reads the session (a damaged file is refused within seconds and said in
a notification) and builds the twin.

The twin is chosen as `station diagnose --twin` chooses it (station.services.twins.load_twin): fitted on
the recording itself (no --twin, the default), the simulated plant (sim:default), or a file typed
in (MODEL.json, REFERENCE.h5 or sim:CONFIG.toml); and, in the UI only, the model on the Results
page.

The report is station.services.diagnosis_jobs.diagnose_session's, as `station diagnose --json` writes it:
on the raw error, with the material temperature range per leg (`material_temperature`), which
the status line and the end of the text show.
"""

from __future__ import annotations

from pathlib import Path

from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.message import Message
from textual.widgets import Button, DataTable, Input, Label, Select, Static

from station.tui.error_text import describe
from station.tui.screens.common import StationScreen
from station.tui.widgets import SessionPicker, sample_folders, XYPlot

# The choices of `station diagnose --twin` (the first, no --twin, is its default), and the model on Results.
TWINS = [("fitted on the recording (default)", "fitted"), ("simulated plant (sim:default)", "sim"),
         ("file: MODEL.json, REFERENCE.h5, sim:CONFIG.toml, fleet:TYPE", "file"),
         ("model on the Results page", "results")]
TWIN_SPEC_HINT = "MODEL.json, REFERENCE.h5, sim:CONFIG.toml or fleet:TYPE"


def twin_spec(kind: str, typed: str = "") -> str | None:
    """What `station diagnose --twin` gets for the choice `kind` (None: no --twin, the twin fitted
    on the recording); "results" has no command-line spelling (save the model, then MODEL.json)."""
    return {"fitted": None, "sim": "sim:default", "file": typed.strip()}.get(kind)


def material_summary(doc: dict | None) -> str:
    """One line for the status: the material temperature range over the legs from the report's
    `material_temperature` (procedures.metrology.thermal.diagnosis_temperature_note; each leg's
    range ends the text). The diagnosis is on the raw error, which the other analyses normalise
    to the reference temperature."""
    from station.services.diagnosis_jobs import material_text

    text = material_text(doc)
    return "[dim]material temperature: not in the report[/dim]" if text is None else text


class DiagnosisReady(Message):
    def __init__(self, path: Path, report: dict, request: int = 0, temp_lines: list[str] | None = None,
                 text: str = "") -> None:
        super().__init__()
        self.path = path
        self.report = report
        self.text = text  # the report as `station diagnose` prints it
        self.temp_lines = temp_lines or []  # the error basis and material temperature, as the CLI prints them
        self.request = request  # the diagnosis request it answers (DiagnosisScreen._request)


class DiagnosisFailed(Message):
    def __init__(self, error: str, request: int = 0) -> None:
        super().__init__()
        self.error = error
        self.request = request


class DiagnosisScreen(StationScreen):
    MODE = "diagnosis"
    PAGE_HELP = "gap = recording − twin: where it lies, which effect explains it, how far it shrinks"
    BINDINGS = [
        Binding("ctrl+o", "open_session", "Open", key_display="^o"),
        Binding("d", "diagnose", "Diagnose"),
        Binding("l", "next_leg", "Next leg"),
    ]

    def compose(self) -> ComposeResult:
        yield from self.compose_header()
        with Vertical(id="diag-body"):
            yield SessionPicker(lambda: [self.app.cfg.recordings_dir, *sample_folders()], id="diag-picker")
            with Horizontal(classes="controls"):
                yield Label("Twin ")
                yield Select(TWINS, value="fitted", allow_blank=False, id="twin", compact=True)
                yield Input(placeholder=TWIN_SPEC_HINT, id="twin-spec", compact=True,
                            tooltip="the twin file or plant config (station diagnose --twin)")
                yield Button("Diagnose (d)", id="diag-run", compact=True, variant="success")
            yield Static("no diagnosis yet: choose a session and press d", id="diag-status", classes="status")
            yield DataTable(id="diag-table", cursor_type="row", zebra_stripes=True)
            with Horizontal(id="diag-plots"):
                yield XYPlot("gap along the stroke", "position mm", "gap µm", id="diag-plot")
                with VerticalScroll(id="diag-text-box"):
                    yield Static("", id="diag-text")
        yield from self.compose_footer()

    CSS = """
    #diag-body .controls Select { width: 50; }
    #diag-body .controls #twin-spec { width: 1fr; }
    """

    def on_mount(self) -> None:
        self.report: dict | None = None
        self.report_text = ""  # the report as `station diagnose` prints it
        self.temp_lines: list[str] = []
        self.plot_leg: str | None = None
        self._request = 0  # numbers the diagnosis requests: only the newest one's answer is shown
        self.running = False
        t = self.query_one("#diag-table", DataTable)
        # the parameters (the widest cells) last, so the figures stay on show on a narrower terminal
        t.add_columns("Leg", "Effect", "Held-out gap µm", "Shrink", "p", "Parameters")
        self.follow_sessions()
        self._show()

    def on_screen_resume(self) -> None:
        if self.app.last_session is not None and not self.query_one("#session-path").value:
            self._on_new_session(self.app.last_session)

    # -- running -----------------------------------------------------------------------------------
    def on_session_picker_chosen(self, message: SessionPicker.Chosen) -> None:
        self.action_diagnose()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "diag-run":
            event.stop()
            self.action_diagnose()

    def on_input_changed(self, event: Input.Changed) -> None:
        if event.input.id == "twin-spec" and event.value.strip():
            self.query_one("#twin", Select).value = "file"  # typing a twin chooses it

    def on_input_submitted(self, event: Input.Submitted) -> None:
        if event.input.id == "twin-spec":
            event.stop()
            self.action_diagnose()

    def twin_kind(self) -> str:
        value = self.query_one("#twin", Select).value
        return "fitted" if value is Select.NULL else str(value)  # allow_blank=False: never NULL

    def action_diagnose(self) -> None:
        text = self.query_one("#session-path").value.strip()
        path = Path(text).expanduser() if text else self.app.last_session
        if path is None:
            self.notify("Choose a session first (a finished sweep appears here).", severity="warning")
            return
        twin_kind = self.twin_kind()
        spec = twin_spec(twin_kind, self.query_one("#twin-spec", Input).value)
        model = None
        if twin_kind == "results":
            if self.app.analysis is None:
                self.notify("No model on the Results screen: fit one there (F3), or choose another twin.",
                            severity="warning")
                return
            model = (self.app.analysis.model, str(self.app.analysis.model_path or self.app.analysis.path))
        elif twin_kind == "file" and not spec:
            self.notify(f"Type the twin beside the list: {TWIN_SPEC_HINT}.", title="Diagnosis", severity="warning")
            return
        self._request += 1
        self.running = True
        self.query_one("#diag-status", Static).update("diagnosing…")
        self._run(Path(path), twin_kind, spec, model, self._request)

    @work(thread=True, exclusive=True, group="diagnosis", exit_on_error=False)
    def _run(self, path: Path, twin_kind: str, spec: str | None, model, request: int = 0) -> None:
        try:
            from station.services.diagnosis_jobs import DiagnoseRequest, prepare_diagnosis

            # the twin as `station diagnose --twin SPEC` chooses it (fleet:TYPE reads the station's catalog, as
            # `station diagnose --config` does), or the Results page's model; the report by the same job
            ask = DiagnoseRequest(path, twin=spec, twin_model=model if twin_kind == "results" else None)
            done = self.app.jobs.run(prepare_diagnosis(ask, self.app.cfg)).data  # the app's one JobRunner
        except Exception as exc:
            self.post_message(DiagnosisFailed(describe(exc, f"cannot diagnose {path.name}"), request))
            return
        self.post_message(DiagnosisReady(path, done.report, request, done.temp_lines, done.text))

    def on_diagnosis_ready(self, message: DiagnosisReady) -> None:
        if message.request != self._request:  # asked for before the last request
            return
        self.running = False
        self.report = message.report
        self.report_text = message.text
        self.report_path = message.path
        self.temp_lines = message.temp_lines
        self.plot_leg = None
        self._show()

    def on_diagnosis_failed(self, message: DiagnosisFailed) -> None:
        if message.request != self._request:
            return
        self.running = False
        self.query_one("#diag-status", Static).update(f"[red]{message.error}[/red]")
        self.notify(message.error, title="Diagnosis", severity="error", timeout=12)

    def action_next_leg(self) -> None:
        if not self.report:
            return
        legs = list(self.report["legs"])
        current = self.plot_leg if self.plot_leg in legs else legs[0]
        self.plot_leg = legs[(legs.index(current) + 1) % len(legs)]
        self._show_plot()

    # -- drawing -------------------------------------------------------------------------------------
    def _show(self) -> None:
        table = self.query_one("#diag-table", DataTable)
        table.clear()
        status = self.query_one("#diag-status", Static)
        text = self.query_one("#diag-text", Static)
        r = self.report
        if r is None:
            text.update("")
            self._show_plot()
            return
        name = self.report_path.name
        n = len(r["findings"])
        status.update(f"[b]{name}[/b]: twin {r['twin']['description']}\n"
                      f"{n} finding{'s' if n != 1 else ''}" + ("" if n else ": no effect is both significant and above the threshold")
                      + "\n" + material_summary(r.get("material_temperature")))
        for f in r["findings"]:
            params = ", ".join(f"{k} {v:.3g}" + (f" ± {f['uncertainty'][k]:.2g}" if f["uncertainty"].get(k) is not None else "")
                               for k, v in f["parameters"].items())
            table.add_row(str(f["leg"]), f["effect"] + (f" ({f['variant']})" if f.get("variant") else ""),
                          f"{f['heldout_rms_before_um']:.3g} → {f['heldout_rms_after_um']:.3g}",
                          f"{f['shrink_pct']:.0f} %", f"{f['p_value']:.2g}", params)
        report_text = self.report_text + ("\n\n" + "\n".join(self.temp_lines) if self.temp_lines else "")
        if self.app.hide_volatile:  # the recording's path and hash vary from run to run
            report_text = "\n".join(line for line in report_text.splitlines() if not line.startswith("recording:"))
        text.update(report_text)
        self._show_plot()

    def _show_plot(self) -> None:
        plot = self.query_one("#diag-plot", XYPlot)
        r = self.report
        if not r or not r["legs"]:
            plot.show([], title="gap along the stroke (no diagnosis)")
            return
        legs = list(r["legs"])
        key = self.plot_leg if self.plot_leg in legs else legs[0]
        self.plot_leg = key
        leg = r["legs"][key]
        # The gap (recording minus twin) per target, mean over the passes of each direction, and
        # its RMS per stroke region as steps.
        series = []
        bt = leg.get("by_target") or {}
        for label, values, kind in (("gap +1 (up)", bt.get("gap_up_um"), "scatter"),
                                    ("gap −1 (down)", bt.get("gap_down_um"), "scatter:x")):
            if values:
                pts = [(x, v) for x, v in zip(bt["position_mm"], values) if v is not None]
                if pts:
                    series.append((label, [p[0] for p in pts], [p[1] for p in pts], kind))
        xs, rms = [], []
        for reg in leg.get("by_region", []):
            for x in (reg["from_mm"], reg["to_mm"]):
                xs.append(x)
                rms.append(reg["rms_um"])
        series.append(("RMS per region", xs, rms, "line"))
        plot.show(series, title=f"leg {key}: gap against position — {leg.get('dominant', '')[:60]}")
