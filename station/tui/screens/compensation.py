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
                yield Button("Make table (t)", id="comp-make", compact=True, variant="success")
                yield Button("Read drives (g)", id="comp-read", compact=True)
                yield Button("Save CSV (w)", id="comp-save", compact=True)
                yield Button("Push… (u)", id="comp-push", compact=True, variant="error")
            yield DataTable(id="comp-table", cursor_type="row", zebra_stripes=True)
            yield Static("", id="comp-status", classes="status")
            with Horizontal(id="comp-plots"):
                yield XYPlot("table", "position mm", "error µm", id="comp-plot")
                yield XYPlot("new − active", "position mm", "µm", id="comp-diff-plot")
        yield from self.compose_footer()

    def on_mount(self) -> None:
        self.table = None  # procedures.table.CompTable
        self.table_model_id: int | None = None
        self.drive_tables: dict[int, DriveTable] = {}
        self.plot_leg: int | None = None
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

    def action_push(self) -> None:
        leg = self._selected_leg()
        if leg is None:
            self.notify("Make a table first (t).", severity="warning")
            return
        push = capabilities.find("push")
        if push is None:
            self.notify(capabilities.missing_text("push", "Pushing a table to a drive") +
                        " Save the table as CSV (w) and push it with `station push` once available.",
                        title="Push", severity="warning", timeout=12)
            return
        if self.app.rig is None:
            self.notify("Not connected to the rig: connect on the Rig screen (F1).", severity="error")
            return
        dt = self.drive_tables.get(leg)
        drive = dt.identity if dt and dt.identity else f"leg {leg} drive"
        where = "" if self.app.hide_volatile else f" at {self.app.cfg.drive.url if not self.app.cfg.is_sim else self.app.rig.description}"
        t = self.table.legs[leg]
        self.app.push_screen(
            ConfirmScreen(
                f"Push the compensation table for [b]leg {leg}[/b] to drive [b]{drive}[/b]{where}?\n\n"
                f"{t.point_count} points from {t.start_mm:+.3f} mm every {t.step_mm:g} mm. The drive's current "
                "table is backed up to the audit log and stays active if anything fails.",
                yes="Push", no="Cancel"),
            lambda yes: self._push_confirmed(yes, leg, push),
        )

    def _push_confirmed(self, yes: bool | None, leg: int, push) -> None:
        if not yes:
            self.notify("Push cancelled; nothing was written.", timeout=4)
            return
        self.notify(f"Pushing the table to leg {leg}…", timeout=4)
        self._push_worker(leg, push)

    @work(thread=True, exclusive=True, group="push", exit_on_error=False)
    def _push_worker(self, leg: int, push) -> None:
        from station.tui.messages import Notice

        app = self.app
        if not app.rig_lock.acquire(timeout=5.0):
            self.post_message(Notice("The rig is busy; push not started.", "error"))
            return
        try:
            push(app.rig.axes[leg], self.table.legs[leg])
        except Exception as exc:
            app.post_message(Notice(describe(exc, f"push to leg {leg} failed") +
                                    " The previous table is still active.", "error", "Push"))
            return
        finally:
            app.rig_lock.release()
        app.post_message(Notice(f"Table pushed to leg {leg} and activated.", "information", "Push"))
        self.call_from_thread(self.action_read_drives)

    def action_verify(self) -> None:
        if capabilities.find("verify") is None:
            self.notify(capabilities.missing_text("verify", "The verification sweep") +
                        " A plain sweep of the leg (F2) with the table active shows the compensated error.",
                        title="Verify", severity="warning", timeout=12)
            return
        self.notify("Verification runs from `station verify` in this build.", severity="warning")

    def action_rollback(self) -> None:
        if capabilities.find("rollback") is None:
            self.notify(capabilities.missing_text("rollback", "Rollback"), title="Rollback", severity="warning", timeout=12)
            return
        self.notify("Rollback runs from `station rollback` in this build.", severity="warning")

    def on_button_pressed(self, event: Button.Pressed) -> None:
        action = {"comp-make": self.action_make_table, "comp-read": self.action_read_drives,
                  "comp-save": self.action_save_csv, "comp-push": self.action_push}.get(event.button.id or "")
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
        lines.append("audit log: " + ("not available yet" if capabilities.find("push") is None else "see `station push` log"))
        status.update("\n".join(lines))
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
