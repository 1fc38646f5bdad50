"""Compensation screen: the table made from the model on show (Results), its difference from the
table active in each drive, export, and push / verify / rollback with a confirmation naming the
leg and the drive.

Tables are made by station.services.table_jobs.make_checked_table (the same as `station table`); errors
are measured minus commanded, um, which the drive subtracts. Push, verify and rollback run the
jobs of station.services.table_jobs through the controller (compensation_controller), exactly as the
command line does: the same procedures, refusals and audit entries. A table or push the service
refuses as a likely unit slip (procedures.metrology.plausibility) is said on the page; a confirmation
dialog then lets the user accept it (the command line's --accept-implausible).
"""

from __future__ import annotations

from rich.markup import escape
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, VerticalScroll
from textual.widgets import Button, DataTable, Input, Label, Static

from station import values
from station.tui.error_text import describe
from station.tui.fields import ValueField
from station.tui.screens.common import ConfirmScreen, FieldRefusal, StationScreen
from station.tui.screens.compensation_controller import (
    UI_ACCEPT_HOW,
    UI_ACCEPTED_AS,
    CompensationController,
    DriveTablesRead,
    TableJobDone,
    VerificationDone,
)
from station.tui.screens.compensation_widgets import AuditTail, DriveTable, LegTablesView, TablePlots


def verdict_line(leg: int, result) -> str:
    """One line: the verification's verdict for `leg` (a leg's result of station.services.verify_job's
    Verification): pass or above the limit, the ratio, the range reduction."""
    from station.services.verify_job import verdict_parts

    verdict, ratio, limit, red = verdict_parts(result)
    if verdict == "none":
        head = f"[yellow b]leg {leg} verification: no verdict[/yellow b] (no repeat passes)"
    elif verdict == "pass":
        head = f"[green b]leg {leg} verification: PASS[/green b], ratio {ratio:.3f} (limit {limit:g})"
    else:
        head = f"[red b]leg {leg} verification: ABOVE the limit[/red b], ratio {ratio:.3f} (limit {limit:g})"
    return head + (f", range reduction {red:.1f} %" if red is not None else "") + "; report below"


class CompensationScreen(StationScreen):
    MODE = "compensation"
    PAGE_HELP = "table = model resampled on a fixed step (error µm, the drive subtracts it); compare, push, verify"
    RIG_KEYS = frozenset({"push", "push_all", "rollback", "verify"})  # act only when pressed on their own
    BINDINGS = [
        Binding("t", "make_table", "Make table"),
        Binding("g", "read_drives", "Read drives"),
        Binding("w", "save_csv", "Save CSV"),
        Binding("u", "push", "Push"),
        Binding("U", "push_all", "Push all legs"),
        Binding("v", "verify", "Verify"),
        Binding("b", "rollback", "Rollback"),
        Binding("l", "next_leg", "Next leg"),
    ]

    def compose(self) -> ComposeResult:
        yield from self.compose_header()
        with VerticalScroll(id="comp-body"):  # a verification report can push the plots below, a scroll away
            yield Static("", id="comp-source", classes="status")
            # the last verification's verdict, on top: its report (below the table) runs past the
            # bottom of an 80x24 terminal
            yield Static("", id="comp-verdict", classes="status")
            with Horizontal(classes="controls split-controls"):  # one row, or two on a narrow terminal
                with Horizontal(classes="control-group"):
                    yield Label("Step mm ")
                    yield ValueField("", id="comp-step", kind=values.STEP_MM, where="step", blank=None,
                                     placeholder="auto", compact=True,
                                     tooltip="table step, mm (blank: the recording's spacing), as station table --step")
                    yield Button("Make (t)", id="comp-make", compact=True, variant="success")
                    yield Button("Read drives (g)", id="comp-read", compact=True)
                    yield Button("CSV (w)", id="comp-save", compact=True)
                with Horizontal(classes="control-group"):
                    yield Button("Push… (u)", id="comp-push", compact=True, variant="error")
                    yield Button("All… (U)", id="comp-push-all", compact=True, variant="error")
                    yield Button("Verify (v)", id="comp-verify", compact=True)
                    yield Button("Rollback… (b)", id="comp-rollback", compact=True)
            yield FieldRefusal("comp-step", id="comp-step-refusal")
            yield LegTablesView(id="comp-table")
            yield Static("", id="comp-status", classes="status")
            yield AuditTail("", id="comp-audit", classes="status")
            yield TablePlots(id="comp-plots")
        yield from self.compose_footer()

    def on_mount(self) -> None:
        self.jobs = CompensationController(self)
        self.table = None  # procedures.compensation.table.CompTable
        self.table_model_id: int | None = None
        self.drive_tables: dict[int, DriveTable] = {}
        self.plot_leg: int | None = None
        self.verify_text = ""
        self.verdict_text = ""  # the last verification's verdict, one line (verdict_line)
        self.slip_text = ""  # a unit-slip refusal, or the warnings of what the user accepted
        self._show()

    def size_changed(self) -> None:
        self.query_one(LegTablesView).show(self.table, self.drive_tables)  # the table's labels for the width
        self._show_audit()

    def on_screen_resume(self) -> None:
        a = self.app.analysis
        if a is not None and id(a.model) != self.table_model_id:
            self.action_make_table()
        else:
            self._show()

    # -- making and exporting ------------------------------------------------------------------------
    def _spec(self):
        """What the connected drives hold (their profile's table), else the built-in drive's."""
        from station.services.wiring import drive_table_spec

        rig = self.app.rig
        if rig is not None and rig.axes:
            spec = rig.axes[min(rig.axes)].table_spec()
            if spec is not None:
                return spec
        return drive_table_spec(self.app.cfg.drive.profile or None)

    def action_make_table(self, accept_implausible: bool = False) -> None:
        from station.services.push_jobs import accept_override
        from station.services.table_jobs import attempt_checked_table

        a = self.app.analysis
        if a is None:
            self.notify("No model yet: fit one on the Results screen (F3, then f).", severity="warning")
            return
        refused = None
        try:
            step = self.query_one("#comp-step", ValueField).read()  # station table --step's parser
            made = attempt_checked_table(a.model, step, self._spec(), accept_implausible=accept_implausible,
                                         override=accept_override(UI_ACCEPT_HOW, UI_ACCEPTED_AS))
            if made.refused is not None:  # a likely unit slip: said here, then the user may accept it
                self.table, refused = None, made.refused
                self.slip_text = f"table refused: {refused}"
            else:
                table = made.table
                # the session's leg serials, so a saved table carries them (# leg_serial:) like `station table`'s
                serials = {leg: s for leg in table.legs if (s := a.session.identity.leg_serial(leg))}
                self.table = type(table)(table.legs, serials or table.serials)
                self.slip_text = "\n".join(made.warnings)
        except ValueError as exc:
            self.table = None
            self.notify(escape(describe(exc, "cannot make the table")), severity="error", timeout=12)
        self.table_model_id = id(a.model)
        self._show()
        if refused is not None:
            self.notify(str(refused), title="Table refused", severity="error", timeout=12)
            self._offer_override(f"[b]Make this table anyway?[/b]\n\n{escape(str(refused))}", "Make anyway",
                                 lambda: self.action_make_table(accept_implausible=True))
        elif self.table is not None and self.app.rig is not None and not self.app.sweep.active:
            self.action_read_drives()

    def _offer_override(self, question: str, yes: str, accept) -> None:
        """The deliberate way past a unit-slip refusal: `accept()` only on an explicit yes."""
        question += ("\n\nOnly if the values are right: they are kept as they are, with a warning"
                     + (" and a note in the audit log." if yes.startswith("Push") else "."))
        self.app.push_screen(ConfirmScreen(question, yes=yes, no="Cancel"), lambda ok: accept() if ok else None)

    def action_save_csv(self) -> None:
        from station.services.table_jobs import write_table

        a = self.app.analysis
        if self.table is None or a is None:
            self.notify("Make a table first (t).", severity="warning")
            return
        from station.tui.widgets import output_folder  # a sample session's table goes to runs/, not recordings/

        out = output_folder(a.path, self.app.cfg.recordings_dir) / f"{a.path.stem}.{a.method}.table.csv"
        try:
            write_table(self.table, out, self.app.cfg, spec=self._spec())
        except Exception as exc:
            self.notify(describe(exc, "cannot write the table"), severity="error", timeout=12)
            return
        self.notify(f"Table written: {out.name if self.app.hide_volatile else out}", timeout=6)

    # -- what the drives hold --------------------------------------------------------------------------
    def action_read_drives(self) -> None:
        busy = self.jobs.refusal("Reading the drives")
        if busy:
            self.notify(busy, severity="warning")
            return
        self.jobs.read_drives(list(self.table.legs) if self.table is not None else sorted(self.app.rig.axes))

    def on_drive_tables_read(self, message: DriveTablesRead) -> None:
        self.drive_tables.update(message.tables)
        self._show()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        if event.input.id == "comp-step":
            event.stop()
            self.action_make_table()

    # -- push, verify, rollback --------------------------------------------------------------------------
    def _selected_leg(self) -> int | None:
        if self.table is None:
            return None
        legs = list(self.table.legs)
        return self.plot_leg if self.plot_leg in legs else legs[0]

    def _ready(self, what: str) -> bool:
        busy = self.jobs.refusal(what)
        if busy:
            self.notify(busy, severity="error" if self.app.rig is None else "warning")
            return False
        return True

    def action_push(self) -> None:
        leg = self._selected_leg()
        if leg is None:
            self.notify("Make a table first (t).", severity="warning")
            return
        if not self._ready("Pushing a table"):
            return
        self.jobs.push(leg, self.table.legs[leg], self._source(leg), self._table_name())

    def action_push_all(self) -> None:
        """Every leg of the table, one confirmation listing each drive and what it gets."""
        if self.table is None:
            self.notify("Make a table first (t).", severity="warning")
            return
        if not self._ready("Pushing the tables"):
            return
        self.jobs.push_all(dict(self.table.legs), {leg: self._source(leg) for leg in self.table.legs},
                           self._table_name())

    def _table_name(self) -> str:
        """How a refusal names the table on show: the model it was made from."""
        a = self.app.analysis
        return f"the table of the {a.method} model of {a.path.name}" if a is not None else "the table"

    def _source(self, leg: int) -> dict | None:
        a = self.app.analysis
        if a is None:
            return None
        source = {"path": str(a.model_path or a.path), "leg": leg, "recording": str(a.path),
                  "recording_sha256": a.session.sha256, "method": a.method}
        serial = a.session.identity.leg_serial(leg)
        if serial:
            source["leg_serial"] = serial  # the push checks it against the leg's configured serial
        return source

    def action_rollback(self) -> None:
        leg = self._selected_leg() or (self.app.legs[0] if self.app.legs else None)
        if leg is not None and self._ready("Rollback"):
            self.jobs.rollback(leg)

    def on_table_job_done(self, message: TableJobDone) -> None:
        text, severity = self.jobs.notice(message)
        self.notify(text, title=message.action.capitalize(), severity=severity,  # type: ignore[arg-type]
                    timeout=12 if severity == "error" else 6)
        if message.accept_again is not None or (message.job is not None and message.job.warnings):
            self.slip_text = text  # the unit-slip refusal (or what was accepted) stays on the page
            self._show()
        self._show_audit()
        if message.accept_again is not None:
            again = message.accept_again

            def push_anyway() -> None:
                if self._ready("Pushing a table"):
                    again()

            self._offer_override(f"[b]Push anyway?[/b]\n\n{escape(message.job.finished.message)}", "Push anyway",
                                 push_anyway)
        if self.app.rig is not None and not self.app.sweep.active:
            self.action_read_drives()

    def action_verify(self) -> None:
        """A verification sweep of the selected leg with its table active: the calibration's plan
        again, then procedures.compensation.verify compares it with the calibration (before vs after)."""
        a = self.app.analysis
        leg = self._selected_leg()
        if a is None or leg is None:
            self.notify("Fit a model (F3) and make its table (t) first: the verification repeats that calibration.",
                        severity="warning")
            return
        if self._ready("The verification sweep") and self.jobs.verify(leg, a):
            self.notify(f"Verification sweep of leg {leg} started (Sweep screen, F2).", timeout=5)
            self.app.switch_mode("sweep")

    def on_verification_done(self, message: VerificationDone) -> None:
        self._show_audit()
        job = message.job
        if job is None or job.data is None:
            return  # refused or broken off: the Sweep page said why
        verification = job.data  # station.services.verify_job.Verification
        result = verification.results[message.leg]
        self.verify_text = verification.report + (f"\nas-left (ISO 14253-1): {verification.as_left_summary}"
                                                  if verification.as_left_summary else "")
        self.verdict_text = verdict_line(message.leg, result)
        line = verification.audit_lines.get(message.leg, "")
        self.notify(line, title="Verify", severity="information" if result.passed else "warning", timeout=12)
        self._show()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        action = {"comp-make": self.action_make_table, "comp-read": self.action_read_drives,
                  "comp-save": self.action_save_csv, "comp-push": self.action_push, "comp-push-all": self.action_push_all,
                  "comp-verify": self.action_verify, "comp-rollback": self.action_rollback}.get(event.button.id or "")
        if action is not None:
            event.stop()
            action()

    def action_next_leg(self) -> None:
        if self.table is None:
            return
        legs = list(self.table.legs)
        self.plot_leg = legs[(legs.index(self._selected_leg()) + 1) % len(legs)]
        self._show_plots()

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        if self.table is not None and event.row_key is not None and event.row_key.value is not None:
            leg = int(event.row_key.value)
            if leg != self.plot_leg:
                self.plot_leg = leg
                self._show_plots()

    # -- drawing -----------------------------------------------------------------------------------------
    def _show(self) -> None:
        a = self.app.analysis
        src = self.query_one("#comp-source", Static)
        if a is None:
            src.update("no model yet: fit one on the Results screen (F3), then come back and press t"
                       + self._targets_text())
        else:
            src.update(f"model: [b]{a.method}[/b] fitted on {a.path.name}"
                       + (f" (saved {a.model_path.name})" if a.model_path else "") + self._targets_text())
        verdict = self.query_one("#comp-verdict", Static)
        verdict.update(self.verdict_text)
        verdict.display = bool(self.verdict_text)
        self.query_one(LegTablesView).show(self.table, self.drive_tables)
        self.query_one("#comp-status", Static).update("\n".join(t for t in (escape(self.slip_text), self.verify_text.rstrip()) if t))
        self._show_audit()
        self._show_plots()

    def _targets_text(self) -> str:
        """"; compensation target: station (every leg), leg 3 drive" where a leg's table is not the
        drive's (the default, also named in every push's confirmation); "" when every leg uses its drive."""
        comp = self.app.cfg.compensation
        parts = [] if comp.target == "drive" else [f"{comp.target} (every leg)"]
        parts += [f"leg {leg} {t}" for leg, t in sorted(comp.legs.items()) if t != comp.target]
        return f"; compensation target: {', '.join(parts)}" if parts else ""

    def _show_audit(self) -> None:
        try:
            entries, error = self.jobs.audit().entries()[-3:], ""
        except Exception as exc:
            entries, error = [], describe(exc)
        # one line an entry: as wide as the page (no wider than the log's usual 112 cells)
        self.query_one(AuditTail).show(entries, error, hide_time=self.app.hide_volatile,
                                       width=min(112, self.app.size.width - 4))

    def _show_plots(self) -> None:
        leg = self._selected_leg()
        self.query_one(TablePlots).show(leg, self.table, self.drive_tables.get(leg) if leg is not None else None)
