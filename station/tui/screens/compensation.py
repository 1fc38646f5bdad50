"""Compensation screen: the table made from the model on show (Results), its difference from the
table active in each drive, export, and push / verify / rollback with a confirmation naming the
leg and the drive.

Tables are made by procedures.table.make_table (the same as `station table`); errors are
measured minus commanded, um, which the drive subtracts. Push, verify and rollback go through
the push procedure when it is installed (see station.tui.capabilities); until then the actions
say so instead of writing anything.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import Button, DataTable, Input, Label, Static

from station.tui import capabilities
from station.tui.errors import describe
from station.tui.messages import Notice
from station.tui.screens.common import ConfirmScreen, StationScreen
from station.tui.widgets import XYPlot


@dataclass
class DriveTable:
    """What one drive holds: its identity, active bank and that bank's table (or why not)."""

    leg: int
    identity: str = ""
    active_bank: int | None = None
    table: Any = None  # drivers.interfaces.TableBank
    error: str = ""


class DriveTablesRead(Message):
    def __init__(self, tables: dict[int, DriveTable]) -> None:
        super().__init__()
        self.tables = tables


class DrivePlanReady(Message):
    """A push or rollback was prepared (drive read, table checked); it awaits confirmation."""

    def __init__(self, plan, audit) -> None:
        super().__init__()
        self.plan = plan
        self.audit = audit


class DriveChanged(Message):
    """A push or rollback ended (either way): re-read the drives and the audit log."""


class VerifyReady(Message):
    def __init__(self, report: str, passed: bool | None, summary: str) -> None:
        super().__init__()
        self.report = report
        self.passed = passed
        self.summary = summary


class CompensationScreen(StationScreen):
    MODE = "compensation"
    PAGE_HELP = "table = model resampled on a fixed step (error µm, the drive subtracts it); compare, push, verify"
    BINDINGS = [
        Binding("t", "make_table", "Make table"),
        Binding("g", "read_drives", "Read drives"),
        Binding("w", "save_csv", "Save CSV"),
        Binding("u", "push", "Push"),
        Binding("v", "verify", "Verify"),
        Binding("b", "rollback", "Rollback"),
        Binding("l", "next_leg", "Next leg"),
    ]

    def compose(self) -> ComposeResult:
        yield from self.compose_header()
        with Vertical(id="comp-body"):
            yield Static("", id="comp-source", classes="status")
            with Horizontal(classes="controls"):
                yield Label("Step mm ")
                yield Input("", id="comp-step", placeholder="auto", type="number", compact=True)
                yield Button("Make (t)", id="comp-make", compact=True, variant="success")
                yield Button("Read drives (g)", id="comp-read", compact=True)
                yield Button("CSV (w)", id="comp-save", compact=True)
                yield Button("Push… (u)", id="comp-push", compact=True, variant="error")
                yield Button("Verify (v)", id="comp-verify", compact=True)
                yield Button("Rollback… (b)", id="comp-rollback", compact=True)
            yield DataTable(id="comp-table", cursor_type="row", zebra_stripes=True)
            yield Static("", id="comp-status", classes="status")
            yield Static("", id="comp-audit", classes="status")
            with Horizontal(id="comp-plots"):
                yield XYPlot("table", "position mm", "error µm", id="comp-plot")
                yield XYPlot("new − active", "position mm", "µm", id="comp-diff-plot")
        yield from self.compose_footer()

    def on_mount(self) -> None:
        self.table = None  # procedures.table.CompTable
        self.table_model_id: int | None = None
        self.drive_tables: dict[int, DriveTable] = {}
        self.plot_leg: int | None = None
        self.verify_text = ""
        t = self.query_one("#comp-table", DataTable)
        t.add_columns("Leg", "Start mm", "Step mm", "Points", "Fwd µm (min..max)", "Rev µm (min..max)",
                      "Drive bank", "Max |new − active| µm")
        self._show()

    def on_screen_resume(self) -> None:
        a = self.app.analysis
        if a is not None and id(a.model) != self.table_model_id:
            self.action_make_table()
        else:
            self._show()

    # -- making and exporting ------------------------------------------------------------------------
    def _limits(self):
        """The drive's table limits from the connected rig's profile (defaults otherwise)."""
        from procedures.table import TableLimits

        profile = getattr(self.app.rig, "profile", None)
        layout = getattr(profile, "table", None)
        kw = {}
        for ours, theirs in (("max_points", "max_points"), ("max_correction_um", "max_correction_um")):
            value = getattr(layout, theirs, None)
            if value is not None:
                kw[ours] = type(getattr(TableLimits(), ours))(value)
        return TableLimits(**kw)

    def action_make_table(self) -> None:
        from procedures.table import make_table

        a = self.app.analysis
        if a is None:
            self.notify("No model yet: fit one on the Results screen (F3, then f).", severity="warning")
            return
        text = self.query_one("#comp-step", Input).value.strip()
        try:
            step = float(text) if text else None
            self.table = make_table(a.model, step_mm=step, limits=self._limits())
        except ValueError as exc:
            self.table = None
            self.notify(describe(exc, "cannot make the table"), severity="error", timeout=12)
        self.table_model_id = id(a.model)
        self._show()
        if self.table is not None and self.app.rig is not None and not self.app.sweep.active:
            self.action_read_drives()

    def action_save_csv(self) -> None:
        from procedures.table import write_table_csv

        a = self.app.analysis
        if self.table is None or a is None:
            self.notify("Make a table first (t).", severity="warning")
            return
        out = a.path.with_name(f"{a.path.stem}.{a.method}.table.csv")
        try:
            write_table_csv(self.table, out, limits=self._limits())
        except Exception as exc:
            self.notify(describe(exc, "cannot write the table"), severity="error", timeout=12)
            return
        self.notify(f"Table written: {out.name if self.app.hide_volatile else out}", timeout=6)

    # -- what the drives hold --------------------------------------------------------------------------
    def action_read_drives(self) -> None:
        if self.app.rig is None:
            self.notify("Not connected to the rig: connect on the Rig screen (F1).", severity="warning")
            return
        if self.app.sweep.active:
            self.notify("A sweep is running: the drives are read after it.", severity="warning")
            return
        legs = list(self.table.legs) if self.table is not None else sorted(self.app.rig.axes)
        self._read_drives(legs)

    @work(thread=True, exclusive=True, group="drive-tables", exit_on_error=False)
    def _read_drives(self, legs: list[int]) -> None:
        app = self.app
        rig = app.rig
        out: dict[int, DriveTable] = {}
        if rig is None or not app.rig_lock.acquire(timeout=5.0):
            return
        try:
            for leg in legs:
                dt = DriveTable(leg)
                axis = rig.axes.get(leg)
                if axis is None:
                    dt.error = "no drive connected for this leg"
                else:
                    try:
                        dt.identity = axis.identity()
                        dt.active_bank = axis.active_bank()
                        dt.table = axis.read_table(dt.active_bank)
                    except Exception as exc:
                        dt.error = describe(exc)
                out[leg] = dt
        finally:
            app.rig_lock.release()
        self.post_message(DriveTablesRead(out))

    def on_input_submitted(self, event: Input.Submitted) -> None:
        if event.input.id == "comp-step":
            event.stop()
            self.action_make_table()

    def on_drive_tables_read(self, message: DriveTablesRead) -> None:
        self.drive_tables.update(message.tables)
        self._show()

    def _active_correction_um(self, leg: int, x_mm: np.ndarray, direction: int) -> np.ndarray | None:
        dt = self.drive_tables.get(leg)
        if dt is None or dt.table is None:
            return None
        tb = dt.table
        if tb.point_count == 0:
            return np.zeros_like(x_mm)  # empty table: the drive corrects nothing
        pos = np.asarray(tb.positions_mm())
        values = tb.error_fwd_um if direction > 0 else tb.error_rev_um
        return np.interp(x_mm, pos, values)

    # -- push, verify, rollback --------------------------------------------------------------------------
    def _selected_leg(self) -> int | None:
        if self.table is None:
            return None
        legs = list(self.table.legs)
        return self.plot_leg if self.plot_leg in legs else legs[0]

    def _audit(self):
        """The audit log `station push/rollback/verify` use: <recordings_dir>/audit.jsonl."""
        from procedures.audit import AuditLog
        from station.commands.push import AUDIT_NAME

        folder = Path(self.app.cfg.recordings_dir)
        folder.mkdir(parents=True, exist_ok=True)
        return AuditLog(folder / AUDIT_NAME, operator=self.app.cfg.operator)

    def _drive_url(self) -> str:
        cfg = self.app.cfg
        if cfg.drive.url == "sim":
            return f"sim ({cfg.sim.nv_path})" if cfg.sim.nv_path else "sim"
        return cfg.drive.url

    def _ready_for_drive(self, what: str) -> bool:
        if capabilities.find("push") is None:
            self.notify(capabilities.missing_text("push", what), severity="warning", timeout=12)
            return False
        if self.app.rig is None:
            self.notify("Not connected to the rig: connect on the Rig screen (F1).", severity="error")
            return False
        if self.app.sweep.active:
            self.notify(f"A sweep is running: {what.lower()} only when it has ended.", severity="warning")
            return False
        return True

    def action_push(self) -> None:
        leg = self._selected_leg()
        if leg is None:
            self.notify("Make a table first (t).", severity="warning")
            return
        if self._ready_for_drive("Pushing a table"):
            self._prepare_worker("push", leg)

    def action_rollback(self) -> None:
        leg = self._selected_leg() or (self.app.legs[0] if self.app.legs else None)
        if leg is not None and self._ready_for_drive("Rollback"):
            self._prepare_worker("rollback", leg)

    @work(thread=True, exclusive=True, group="push", exit_on_error=False)
    def _prepare_worker(self, action: str, leg: int) -> None:
        """Read the drive and check what would be written (nothing is written here)."""
        from procedures.audit import AuditEntry
        from procedures.push import PushRefused, prepare_push, prepare_rollback

        app = self.app
        audit = self._audit()
        url = self._drive_url()
        source = None
        a = app.analysis
        if action == "push" and a is not None:
            source = {"path": str(a.model_path or a.path), "leg": leg, "recording": str(a.path),
                      "recording_sha256": a.session.sha256, "method": a.method}
        if not app.rig_lock.acquire(timeout=5.0):
            app.post_message(Notice("The rig is busy; try again.", "error", action.capitalize()))
            return
        try:
            axis = app.rig.axes[leg]
            if action == "push":
                profile = app.rig.profile
                plan = prepare_push(axis, self.table.legs[leg], table_limits=self._limits(),
                                    quantum_um=profile.table.entry_scale_um if profile else 0.01,
                                    drive_url=url, source=source)
            else:
                plan = prepare_rollback(axis, audit, drive_url=url)
        except Exception as exc:
            if isinstance(exc, PushRefused):
                try:
                    audit.append(AuditEntry(action, leg, "refused", str(exc), "", url, app.cfg.operator, source=source))
                except Exception:
                    pass  # the refusal is still shown; the log is best effort here as in the CLI
            app.post_message(Notice(describe(exc, f"{action} refused"), "error", action.capitalize()))
            return
        finally:
            app.rig_lock.release()
        self.post_message(DrivePlanReady(plan, audit))

    def on_drive_plan_ready(self, message: DrivePlanReady) -> None:
        plan = message.plan
        lines = plan.describe()
        if self.app.hide_volatile:
            lines = [line.split(" at ")[0] if line.startswith(f"leg {plan.leg}: drive") else line for line in lines]
        verb = "Push this table to" if plan.action == "push" else "Roll back the table of"
        question = f"[b]{verb} leg {plan.leg}[/b], drive [b]{plan.drive}[/b]?\n\n" + "\n".join(lines) + (
            "\n\nThe drive's current table is backed up in the audit log first; on any failure it stays active.")
        self.app.push_screen(ConfirmScreen(question, yes="Push" if plan.action == "push" else "Roll back", no="Cancel"),
                             lambda yes: self._confirmed(yes, message.plan, message.audit))

    def _confirmed(self, yes: bool | None, plan, audit) -> None:
        from procedures.audit import AuditEntry

        if not yes:
            try:
                audit.append(AuditEntry(plan.action, plan.leg, "cancelled", "cancelled at the confirmation; nothing written",
                                        plan.drive, plan.drive_url, self.app.cfg.operator, source=plan.source))
            except Exception:
                pass
            self.notify(f"{plan.action.capitalize()} cancelled; nothing was written.", timeout=5)
            self._show_audit()
            return
        self.notify(f"{'Pushing to' if plan.action == 'push' else 'Rolling back'} leg {plan.leg}…", timeout=4)
        self._apply_worker(plan, audit)

    @work(thread=True, exclusive=True, group="push", exit_on_error=False)
    def _apply_worker(self, plan, audit) -> None:
        from procedures.push import push_table, rollback

        app = self.app
        if not app.rig_lock.acquire(timeout=5.0):
            app.post_message(Notice("The rig is busy; nothing was written.", "error", plan.action.capitalize()))
            return
        try:
            axis = app.rig.axes[plan.leg]
            if plan.action == "push":
                result = push_table(axis, plan=plan, audit=audit, operator=app.cfg.operator)
            else:
                result = rollback(axis, audit, plan=plan, operator=app.cfg.operator)
        except Exception as exc:  # PushRefused / PushFailed say which table is active
            app.post_message(Notice(describe(exc, f"{plan.action} of leg {plan.leg} failed"), "error", plan.action.capitalize()))
            self.post_message(DriveChanged())
            return
        finally:
            app.rig_lock.release()
        done = "pushed and active" if plan.action == "push" else "rolled back"
        warn = "" if result.table_enabled else " Warning: the drive does not apply its table (table_enable = 0)."
        app.post_message(Notice(f"Leg {result.leg}: table {done} in bank {result.bank} (was bank {result.previous_bank}); "
                                f"backup in the audit log.{warn}", "information", plan.action.capitalize()))
        self.post_message(DriveChanged())

    def on_drive_changed(self, message: DriveChanged) -> None:
        self._show_audit()
        self.action_read_drives()

    def action_verify(self) -> None:
        """A verification sweep of the selected leg with its table active: the calibration's plan
        again, then procedures.verify compares it with the calibration (before vs after)."""
        from dataclasses import replace

        from procedures.plans import SweepPlan

        a = self.app.analysis
        leg = self._selected_leg()
        if a is None or leg is None:
            self.notify("Fit a model (F3) and make its table (t) first: the verification repeats that calibration.",
                        severity="warning")
            return
        if not self._ready_for_drive("The verification sweep"):
            return
        dt = self.drive_tables.get(leg)
        if dt is None or dt.table is None:
            self.notify("Read the drives first (g).", severity="warning")
            return
        if dt.table.point_count == 0:
            self.notify(f"Leg {leg}: the drive's active table is empty; push a table first (u).", severity="error")
            return
        try:
            plan = replace(SweepPlan.from_dict(a.session.plan), legs=(leg,), kind="verification", notes=())
        except Exception as exc:
            self.notify(describe(exc, "the calibration's plan cannot be repeated"), severity="error", timeout=12)
            return
        from station.tui.app import default_session_path

        made = default_session_path(self.app.cfg, (leg,))  # runs/ui-STAMP-legN.h5
        out = made.with_name("verify-" + made.name.removeprefix("ui-"))
        before = a.session
        if self.app.start_sweep(plan, out, label=f"verification of leg {leg}",
                                on_done=lambda state: self._verify_done(state, before, leg, dt)):
            self.notify(f"Verification sweep of leg {leg} started (Sweep screen, F2).", timeout=5)
            self.app.switch_mode("sweep")

    def _verify_done(self, state, before, leg: int, dt: DriveTable) -> None:
        if state.out is None or not state.out.exists():
            return
        self._verify_worker(state.out, state.status, before, leg, dt)

    @work(thread=True, exclusive=True, group="verify", exit_on_error=False)
    def _verify_worker(self, out: Path, outcome: str, before, leg: int, dt: DriveTable) -> None:
        from procedures.audit import AuditEntry
        from procedures.push import table_sha256
        from procedures.recording.reader import read_session
        from procedures.verify import ACCEPT_RATIO, format_report, verify

        app = self.app
        try:
            after = read_session(out)
            results = verify(after.points, before.points, [leg], after_source=str(out), before_source=str(before.path))
        except Exception as exc:
            app.post_message(Notice(describe(exc, "cannot evaluate the verification"), "error", "Verify"))
            return
        r = results[leg]
        ratio = r.ratio
        msg = (f"verification {outcome}: residual RMS {r.after.rms_um:.4f} um, noise floor "
               + (f"{r.after.noise_floor_um:.4f} um, ratio {ratio:.3f} ({'pass' if r.passed else 'above'} {ACCEPT_RATIO:g})"
                  if ratio is not None else "n/a"))
        try:
            self._audit().append(AuditEntry(
                "verify", leg, outcome, msg, dt.identity, self._drive_url(), app.cfg.operator,
                table_sha256=table_sha256(dt.table), bank=dt.active_bank,
                details={"session": str(out), "session_sha256": after.sha256, **r.to_json(),
                         "before_session": {"path": str(before.path), "sha256": before.sha256}}))
        except Exception as exc:
            app.post_message(Notice(describe(exc, "the audit log"), "warning", "Verify"))
        self.post_message(VerifyReady(format_report(results), r.passed, msg))

    def on_verify_ready(self, message: VerifyReady) -> None:
        self.verify_text = message.report
        self.notify(message.summary, title="Verify", severity="information" if message.passed else "warning", timeout=12)
        self._show()

    def _show_audit(self) -> None:
        widget = self.query_one("#comp-audit", Static)
        try:
            entries = self._audit().entries()[-3:]
        except Exception as exc:
            widget.update(f"audit log: [red]{describe(exc)}[/red]")
            return
        if not entries:
            widget.update("audit log: no entries yet")
            return
        lines = ["audit log (newest last):"]
        for e in entries:
            when = "" if self.app.hide_volatile else f"{e.time_utc[:19]} "
            head = f"  {when}{e.action} leg {e.leg} {e.outcome}: "
            message = e.message if len(head) + len(e.message) <= 112 else e.message[:109 - len(head)] + "…"
            lines.append(f"{head}{message}".replace("[", "\\["))
        widget.update("\n".join(lines))

    def on_button_pressed(self, event: Button.Pressed) -> None:
        action = {"comp-make": self.action_make_table, "comp-read": self.action_read_drives,
                  "comp-save": self.action_save_csv, "comp-push": self.action_push,
                  "comp-verify": self.action_verify, "comp-rollback": self.action_rollback}.get(event.button.id or "")
        if action is not None:
            event.stop()
            action()

    def action_next_leg(self) -> None:
        if self.table is None:
            return
        legs = list(self.table.legs)
        current = self._selected_leg()
        self.plot_leg = legs[(legs.index(current) + 1) % len(legs)]
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
            src.update("no model yet: fit one on the Results screen (F3), then come back and press t")
        else:
            name = a.path.name
            src.update(f"model: [b]{a.method}[/b] fitted on {name}" + (f" (saved {a.model_path.name})" if a.model_path else ""))
        table = self.query_one("#comp-table", DataTable)
        table.clear()
        if self.table is not None:
            for leg, t in self.table.legs.items():
                dt = self.drive_tables.get(leg)
                if dt is None:
                    bank, diff = "–", "–"
                elif dt.error:
                    bank, diff = "[red]?[/red]", dt.error[:40]
                else:
                    bank = f"{dt.active_bank} ({dt.table.point_count} pts)"
                    x = t.positions_mm
                    d = max(float(np.max(np.abs(np.asarray(t.error_fwd_um) - self._active_correction_um(leg, x, 1)))),
                            float(np.max(np.abs(np.asarray(t.error_rev_um) - self._active_correction_um(leg, x, -1)))))
                    diff = f"{d:.3f}"
                table.add_row(str(leg), f"{t.start_mm:+.3f}", f"{t.step_mm:g}", str(t.point_count),
                              f"{min(t.error_fwd_um):+.3f}..{max(t.error_fwd_um):+.3f}",
                              f"{min(t.error_rev_um):+.3f}..{max(t.error_rev_um):+.3f}", bank, diff, key=str(leg))
        status = self.query_one("#comp-status", Static)
        missing = [label for what, label in (("push", "push"), ("verify", "verify"), ("rollback", "rollback"))
                   if capabilities.find(what) is None]
        lines = []
        if missing:
            lines.append(f"[yellow]not available yet in this build: {', '.join(missing)}[/yellow] "
                         "(the table can be saved as CSV: w)")
        if self.verify_text:
            lines.append(self.verify_text.rstrip())
        status.update("\n".join(lines))
        self._show_audit()
        self._show_plots()

    def _show_plots(self) -> None:
        plot = self.query_one("#comp-plot", XYPlot)
        diff = self.query_one("#comp-diff-plot", XYPlot)
        leg = self._selected_leg()
        if leg is None:
            plot.show([], title="table (none yet)")
            diff.show([], title="new − active (none yet)")
            return
        t = self.table.legs[leg]
        x = t.positions_mm
        series = [("new fwd (+1)", x, t.error_fwd_um, "line"), ("new rev (−1)", x, t.error_rev_um, "line")]
        dseries = []
        fwd_active = self._active_correction_um(leg, x, 1)
        if fwd_active is not None:
            rev_active = self._active_correction_um(leg, x, -1)
            series += [("active fwd", x, fwd_active, "line"), ("active rev", x, rev_active, "line")]
            dseries = [("fwd", x, np.asarray(t.error_fwd_um) - fwd_active, "line"),
                       ("rev", x, np.asarray(t.error_rev_um) - rev_active, "line")]
        plot.show(series, title=f"leg {leg}: table, {t.point_count} points every {t.step_mm:g} mm")
        diff.show(dseries, title=f"leg {leg}: new − active" + ("" if dseries else " (drive not read: g)"))
