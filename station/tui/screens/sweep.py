"""Sweep screen: choose legs and plan, start; live error plot, progress, environment; pause,
resume, abort; finish an aborted session (r: `StationApp.resume_sweep`, the job of `station
sweep --resume`). The sweep itself belongs to the app, so leaving this screen does not stop it.

The screen draws `app.sweep` when the app says it changed (a `SweepChanged` message, coalesced
by the app), when it is shown again, and after the operator's own actions here; it never polls.
"""

from __future__ import annotations

from pathlib import Path

from rich.markup import escape
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Grid, Horizontal, Vertical, VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Button, Input, Label, ProgressBar, Select, Static

from station import values as V
from station.services.sweep_job import DEFAULT_CYCLES, SweepRequest, SweepSize, build_plan_of, estimate, plan_spec_of
from station.progress import fmt_duration
from station import values
from station.tui.error_text import describe
from station.tui.fields import FIELD_KINDS, ValueField
from station.tui.messages import SweepChanged
from station.tui.screens.common import ConfirmScreen, StationScreen
from station.tui.widgets import XYPlot, known_sessions

PLANS = [("ISO 230-2", "iso230"), ("Paper (361 × 0.5 mm)", "paper"), ("On the fly", "onthefly"),
         ("On the fly, adaptive", "onthefly-adaptive")]
ONTHEFLY = ("onthefly", "onthefly-adaptive")


class SweepScreen(StationScreen):
    MODE = "sweep"
    AUTO_FOCUS = "#start"
    PAGE_HELP = "choose legs and plan, start; error = measured − commanded (µm)"
    RIG_KEYS = frozenset({"start", "pause_sweep", "resume_session"})  # act only when pressed on their own
    BINDINGS = [
        Binding("s", "start", "Start"),
        Binding("p", "app.pause_sweep", "Pause/Resume"),
        Binding("a", "app.abort_sweep", "Abort"),
        Binding("l", "next_leg", "Plot next leg"),
        Binding("r", "resume_session", "Resume aborted"),
    ]

    def compose(self) -> ComposeResult:
        yield from self.compose_header()
        with Horizontal(id="sweep-body"):
            with VerticalScroll(id="sweep-form"):
                with Grid(id="plan-grid"):
                    yield Label("Legs")
                    yield Input("1", id="legs", compact=True, tooltip="e.g. 1, 1-6 or 1,3")
                    yield Label("Plan")
                    yield Select(PLANS, value="iso230", allow_blank=False, id="plan", compact=True)
                    yield Label("Cycles")
                    # blank: the plan's standard number (DEFAULT_CYCLES), as --cycles left out
                    yield ValueField("5", id="cycles", kind=FIELD_KINDS["cycles"][0], where="cycles", blank=None, compact=True,
                                     tooltip="bidirectional cycles (blank: the plan's standard)")
                    yield Label("Targets")
                    yield ValueField("11", id="n-targets", kind=FIELD_KINDS["n-targets"][0], where="targets", blank=None, compact=True,
                                     tooltip="number of irregularly spaced targets (ISO 230-2; blank: the minimum)")
                    yield Label("Step mm")
                    yield ValueField("", id="step", kind=values.STEP_MM, where="step", blank=None,
                                     placeholder="blank: irregular", compact=True,
                                     tooltip="uniform spacing instead of irregular targets, mm (a decimal point: 2.5)")
                    yield Label("Min mm")
                    yield ValueField("-90", id="min-mm", kind=values.POSITION_MM, where="min mm", blank=-90.0,
                                     compact=True, tooltip="lowest target, mm (blank: -90)")
                    yield Label("Max mm")
                    yield ValueField("90", id="max-mm", kind=values.POSITION_MM, where="max mm", blank=90.0,
                                     compact=True, tooltip="highest target, mm (blank: +90)")
                    yield Label("Dwell s")
                    yield ValueField("1", id="dwell", kind=values.TIME_S, where="dwell", blank=1.0, compact=True,
                                     tooltip="settle time per target, s (blank: 1)")
                    yield Label("Serials")
                    # a short placeholder: the field is 20-odd cells wide even at 120 columns
                    yield Input("", id="serials", placeholder="e.g. 3=HX-0042", compact=True,
                                tooltip="each selected leg's serial, LEG=SERIAL separated by spaces (blank: the "
                                        "config's serials); recorded in the session and checked by push (like "
                                        "station sweep --serial)")
                yield Static("", id="plan-summary")
                yield Button("Start (s)", id="start", variant="success")
                with Horizontal(classes="pair"):
                    yield Button("Pause (p)", id="pause", variant="warning")
                    yield Button("Abort (a)", id="abort", variant="error")
            with Vertical(id="sweep-live"):
                yield XYPlot("error against position", "target mm", "error µm", id="sweep-plot")
                yield ProgressBar(id="progress", show_eta=False)
                yield Static("no sweep yet", id="sweep-status")
                yield Static("", id="sweep-env")
                yield Static("", id="sweep-faults")
        yield from self.compose_footer()

    def on_mount(self) -> None:
        self.plot_leg: int | None = None
        self.size_changed()
        self._update_summary()
        self._redraw()

    def on_screen_resume(self) -> None:
        self._redraw()

    def size_changed(self) -> None:
        # a short terminal: one-line buttons, so the whole form (legs, plan, Start, Abort) is on show
        for button in self.query("#sweep-form Button").results(Button):
            button.compact = self.short

    def on_sweep_changed(self, message: SweepChanged) -> None:
        self._redraw()

    # -- form --------------------------------------------------------------------------------------
    def request(self, serials: dict | None = None) -> SweepRequest:
        """The sweep the form asks for, as the services' request (InputError naming the field
        that is wrong); recorded to a new session file under the recordings folder."""
        def val(wid: str) -> str:
            return self.query_one(f"#{wid}", Input).value.strip()

        def num(wid: str):
            # the field's kind's parser (station.values, the command line's): InputError naming it
            return self.query_one(f"#{wid}", ValueField).read()

        kind = self.query_one("#plan", Select).value
        legs = V.LEGS.parse(val("legs") or "1", "legs")  # --legs's kind; its numbers are the request's
        cycles, dwell_s = num("cycles"), num("dwell")
        n_targets = None if kind in ONTHEFLY else num("n-targets")  # on the fly: evenly spaced, by the step
        step_mm = None if kind == "paper" else num("step")  # the paper plan has fixed targets
        min_mm, max_mm = num("min-mm"), num("max-mm")
        return SweepRequest(legs=legs, kind=kind, cycles=cycles, n_targets=n_targets, step_mm=step_mm,
                            min_mm=min_mm, max_mm=max_mm, dwell_s=dwell_s, serials=serials or {}, make_parents=True)

    def plan_spec(self):
        """The plan the form asks for (procedures' PlanSpec, as `station sweep` makes it)."""
        return plan_spec_of(self.request())

    def build_plan(self):
        """The plan from the form, built exactly as `station sweep` builds it."""
        return build_plan_of(self.request())

    def serials(self, legs) -> dict[int, dict[str, str]]:
        """The Serials field as `station sweep --serial` takes it (InputError naming what is
        wrong); a serial for a leg the plan does not sweep is refused."""
        from station.services.session_identity import leg_fields
        from station.services.serials import parse_serial_args

        entered = parse_serial_args(self.query_one("#serials", Input).value.replace(",", " ").split())
        other = sorted(set(entered) - set(legs))
        if other:
            raise ValueError(f"serials: leg(s) {other} are not swept (legs {list(legs)})")
        leg_fields(self.app.cfg, entered)  # a bad serials file in the config is said before the start
        return entered
    def plan_size(self) -> SweepSize:
        """The size of the plan the form asks for, from the form alone (nothing built), and
        whether the config's [limits] take it."""
        return estimate(self.request(), self.app.cfg)

    def _update_summary(self) -> None:
        summary = self.query_one("#plan-summary", Static)
        kind = self.query_one("#plan", Select).value
        paper = kind == "paper"
        for wid in ("n-targets", "step", "min-mm", "max-mm"):
            self.query_one(f"#{wid}", Input).disabled = (paper or self.app.sweep.active
                                                         or (wid == "n-targets" and kind in ONTHEFLY))
        try:
            size = self.plan_size()
            if size.over_limits:  # sized, never built here: a huge plan would take seconds per key
                summary.update(f"[yellow b]{size.text}[/yellow b]: beyond the config's \\[limits]; Start asks "
                               "first")
                return
            plan = self.build_plan()
        except Exception as exc:
            summary.update(f"[red]{escape(describe(exc))}[/red]")  # typed text is not markup
            return
        if plan.onthefly:
            speeds = " and ".join(f"{v:g}" for v in plan.speeds_mm_s)
            text = (f"{len(plan.targets_mm)} positions every {plan.step_mm:g} mm captured on the fly at {speeds} mm/s, "
                    f"+1 anchor per pass × {plan.cycles} cycles{' at most' if plan.adaptive else ''} × 2 directions × "
                    f"{len(plan.legs)} leg(s) = [b]{plan.total_points}[/b] points, about "
                    f"{fmt_duration(plan.estimated_duration_s(0))} on the rig")
        else:
            text = (f"{len(plan.targets_mm)} targets × {plan.cycles} cycles × 2 directions × "
                    f"{len(plan.legs)} leg(s) = [b]{plan.total_points}[/b] points")
        text += f"; a {size.bytes_text} session file"
        for note in plan.notes:
            text += f"\n[yellow]note:[/yellow] {note}"
        summary.update(text)

    def on_input_changed(self, event: Input.Changed) -> None:
        self._update_summary()

    def on_select_changed(self, event: Select.Changed) -> None:
        # each plan has its own standard number of cycles (ISO 230-2: 5, the paper: 6 sets)
        cycles = self.query_one("#cycles", Input)
        default = {kind: str(n) for kind, n in DEFAULT_CYCLES.items()}
        if cycles.value.strip() in ("", *default.values()):
            cycles.value = default.get(str(event.value), cycles.value)
        self._update_summary()

    # -- actions -----------------------------------------------------------------------------------
    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        if event.button.id == "start":
            self.action_start()
        elif event.button.id == "pause":
            self.app.action_pause_sweep()
        elif event.button.id == "abort":
            self.app.action_abort_sweep()

    def action_start(self) -> None:

        if self.app.sweep.active:
            self.notify("A sweep is already running.", severity="warning")
            return
        try:
            request = self.request()
            request.serials = self.serials(plan_spec_of(request).legs)  # said before anything is asked or built
            size = estimate(request, self.app.cfg)  # before anything is built
            if size.over_limits:
                limits = self.app.cfg.limits
                question = (f"This plan has [b]{size.text}[/b]: beyond the config's \\[limits] "
                            f"(max_points {limits.max_points}, max_rig_hours {limits.max_rig_hours:g}).\n\n"
                            "Start it anyway? Abort (a) or quitting stops it at any moment.")
                # accepted: built in the job's worker, where an abort ends the building at once
                request.beyond_limits = request.build_in_run = True
                self.app.push_screen(ConfirmScreen(question, yes="Start anyway", no="Cancel"),
                                     lambda yes: self._start(request) if yes else None)
                return
        except Exception as exc:
            self.notify(escape(describe(exc)), title="Plan", severity="error", timeout=10)
            return
        self._start(request)

    def _start(self, request: SweepRequest) -> None:
        """Start the sweep `request` asks for, recorded to a new session file."""
        from station.services.sessions import default_session_path

        request.out = default_session_path(self.app.cfg, plan_spec_of(request).legs)
        if self.app.start_sweep(request):
            self.plot_leg = None
            self.query_one("#abort", Button).focus()
            self._redraw()

    def resumable_default(self) -> Path | None:
        """The session `r` offers: the last sweep here if it was aborted or failed, else the
        newest session made or opened in this UI (None: none yet)."""
        s = self.app.sweep
        if s.label == "sweep" and s.status in ("aborted", "failed", "error") and s.out is not None and s.out.exists():
            return s.out
        last = self.app.last_session
        return last if last is not None and Path(last).exists() else None

    def action_resume_session(self) -> None:
        """Ask which session to finish (the last aborted one offered), then resume it."""
        refusal = self.app.sweep_refusal()
        if refusal:
            self.notify(refusal, title="Resume", severity="warning")
            return

        def chosen(path: Path | None) -> None:
            if path is not None and self.app.resume_sweep(path):
                self.plot_leg = None
                self.query_one("#abort", Button).focus()
                self._redraw()

        self.app.push_screen(ResumeScreen(self.resumable_default(), [self.app.cfg.recordings_dir]), chosen)

    def action_next_leg(self) -> None:
        legs = sorted(self.app.sweep.traces)
        if not legs:
            return
        current = self.plot_leg or self.app.sweep.current_leg or legs[0]
        self.plot_leg = legs[(legs.index(current) + 1) % len(legs)] if current in legs else legs[0]
        self._redraw()

    # -- drawing -----------------------------------------------------------------------------------
    def _redraw(self) -> None:
        s = self.app.sweep
        active = s.active
        if active != getattr(self, "_form_locked", None):  # the form is locked while a sweep runs
            self._form_locked = active
            for wid in ("legs", "plan", "cycles", "dwell", "serials"):
                self.query_one(f"#{wid}").disabled = active
            self._update_summary()
        self.query_one("#start", Button).disabled = active
        self.query_one("#pause", Button).disabled = not active
        self.query_one("#abort", Button).disabled = not active
        self.query_one("#pause", Button).label = "Resume (p)" if s.status == "paused" else "Pause (p)"

        leg = self.plot_leg if self.plot_leg in s.traces else s.current_leg
        plot = self.query_one("#sweep-plot", XYPlot)
        trace = s.traces.get(leg) if leg is not None else None
        if trace is None:
            plot.show([], title="error against position (no points yet)")
        else:
            plot.show([
                ("approach +1 (up)", trace.up_target_mm, trace.up_error_um, "scatter"),
                ("approach −1 (down)", trace.down_target_mm, trace.down_error_um, "scatter:x"),
            ], title=f"leg {leg}: error against position ({trace.count} points)", xlim=s.target_span)

        bar = self.query_one("#progress", ProgressBar)
        # never indeterminate: its animation would be a moving part on an idle screen
        bar.update(total=max(s.total, 1), progress=s.done)

        status = self.query_one("#sweep-status", Static)
        if s.status == "idle":
            status.update("no sweep yet: fill in the plan and press Start (s)")
        else:
            colour = {"completed": "green", "aborted": "yellow", "failed": "red", "error": "red",
                      "paused": "yellow", "aborting": "yellow"}.get(s.status, "cyan")
            line = f"{s.label}: [{colour} b]{s.status}[/{colour} b]  {s.done}/{s.total} points"
            if s.resumed_points:
                line += f" ({s.resumed_points} recorded before the resume)"
            r = s.last_record
            if r:
                line += (f"   leg {int(r['leg'])} run {int(r['run'])} {r['target_mm']:+.3f} mm "
                         f"error {r['error_um']:+.3f} µm")
            if not self.app.hide_volatile:
                if active:
                    line += f"   elapsed {fmt_duration(s.elapsed_s)}  ETA {fmt_duration(s.eta_s)}"
                if s.out is not None:
                    line += f"\nrecording: {s.out}"
            if s.reason and s.status not in ("running", "paused"):
                line += f"\n{s.reason}"
            if s.note:
                line += f"\n{s.note}"
            status.update(line)

        env = self.query_one("#sweep-env", Static)
        r = s.last_record
        if r:
            env.update(f"air {r['air_temp_c']:.2f} °C  {r['air_pressure_hpa']:.1f} hPa  {r['humidity_pct']:.1f} %RH"
                       f"   material {r['material_temp_c']:.2f} °C   load {r['load_n']:.0f} N   signal {r['signal_pct']:.0f} %")
        else:
            env.update("")
        faults = self.query_one("#sweep-faults", Static)
        lines = [f"[cyan]adaptive[/cyan] leg {e.leg}: stopped after {e.cycles} cycles: {e.reason}"
                 for e in getattr(s, "stops", [])[-3:]]
        lines += [f"[cyan]probes[/cyan] leg {e.leg}: {e.pairs} pairs: {e.reason}" for e in getattr(s, "probe_stops", [])[-3:]]
        lines += [f"[yellow]fault[/yellow] leg {f.leg} run {f.run} {f.target_mm:+.3f} mm: "
                  f"{f.kind} (attempt {f.attempt}{', gave up' if f.gave_up else ''})" for f in s.faults[-3:]]
        faults.update("\n".join(lines))


class ResumeScreen(ModalScreen["Path | None"]):
    """Which aborted session to finish: `default` (the last aborted sweep) offered, or one of
    the recent sessions, or a path typed in. Dismisses with the path, or None (Esc)."""

    BINDINGS = [Binding("escape", "cancel", "Cancel")]

    def __init__(self, default: Path | None, folders) -> None:
        super().__init__()
        self.default = default
        self.folders = folders

    def compose(self) -> ComposeResult:
        with Vertical(id="resume-dialog"):
            yield Static("[b]Resume an aborted sweep[/b]\nThe session's own plan is finished on its legs, appending "
                         "to the same file (as `station sweep --resume`): [b]the legs move[/b]. A complete or "
                         "imported session is refused.", id="resume-about")
            yield Select([(str(p), str(p)) for p in known_sessions(self.folders)], prompt="recent sessions",
                         id="resume-list", compact=True)
            yield Input(str(self.default or ""), placeholder="session file: FILE.h5", id="resume-path", compact=True)
            with Horizontal(id="resume-buttons"):
                yield Button("Resume (Enter)", id="resume-yes", variant="warning")
                yield Button("Cancel (Esc)", id="resume-no", variant="primary")

    def on_mount(self) -> None:
        self.query_one("#resume-path", Input).focus()

    def on_select_changed(self, event: Select.Changed) -> None:
        event.stop()
        # nothing chosen leaves the path as it is: Textual 8's "no selection" is Select.NULL
        # (Select.BLANK is False and never equals it, so the path became the text "Select.NULL")
        if event.value is not Select.NULL:
            self.query_one("#resume-path", Input).value = str(event.value)

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self._resume()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        if event.button.id == "resume-yes":
            self._resume()
        else:
            self.dismiss(None)

    def _resume(self) -> None:
        text = self.query_one("#resume-path", Input).value.strip()
        if not text:
            self.notify("Choose a recent session or type the path of the session file to finish (.h5).",
                        title="Resume", severity="warning")
            return
        self.dismiss(Path(text).expanduser())

    def action_cancel(self) -> None:
        self.dismiss(None)
