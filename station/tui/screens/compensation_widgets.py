"""The Compensation page's widgets: the table per leg beside what each drive holds, the two
plots (table, new minus active) and the tail of the audit log. They only draw what they are given.

Errors are measured minus commanded, um; the drive subtracts its table from the command.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from textual.containers import Horizontal
from textual.widgets import DataTable, Static

from station.tui.widgets import XYPlot, fit_columns


@dataclass
class DriveTable:
    """What one leg's table holder holds: the drive's identity, the compensation `target`
    ("drive": the drive's banks; "station": the station's table store), the active bank and
    that bank's table (or why not)."""

    leg: int
    identity: str = ""
    target: str = "drive"
    active_bank: int | None = None
    table: Any = None  # drivers.interfaces.TableBank
    error: str = ""

    def correction_um(self, x_mm: np.ndarray, direction: int) -> np.ndarray | None:
        """The active table's correction at `x_mm` for approach `direction` (+1/-1) as the drive
        interpolates it (linear, ends held); zeros for an empty table; None when not read."""
        if self.table is None:
            return None
        if self.table.point_count == 0:
            return np.zeros_like(x_mm)  # empty table: the drive corrects nothing
        values = self.table.error_fwd_um if direction > 0 else self.table.error_rev_um
        return np.interp(x_mm, np.asarray(self.table.positions_mm()), values)


class LegTablesView(DataTable):
    """One row per leg: the new table's span and range, the drive's active bank, and the largest
    difference between the new table and the active one."""

    COLUMNS = ("Leg", "Start mm", "Step mm", "Points", "Fwd µm (min..max)", "Rev µm (min..max)",
               "Drive bank", "Max |new − active| µm")
    # A narrow terminal: shorter labels, and what the push and verify are about (the table's
    # range, the drive's bank, the difference) beside the leg; the table's span last.
    NARROW = (("Leg", "Fwd µm", "Rev µm", "Bank", "|Δ| µm", "Pts", "Step", "Start mm"), (0, 4, 5, 6, 7, 3, 2, 1))

    def on_mount(self) -> None:
        self.cursor_type = "row"
        self.zebra_stripes = True
        self.add_columns(*self.COLUMNS)

    def show(self, table, drives: dict[int, DriveTable]) -> None:
        self.clear()
        rows = []
        for leg, t in (table.legs.items() if table is not None else ()):
            dt = drives.get(leg)
            if dt is None:
                bank, diff = "–", "–"
            elif dt.error:
                bank, diff = "[red]?[/red]", dt.error[:40]
            else:
                bank = f"{dt.active_bank} ({dt.table.point_count} pts)" + (" station" if dt.target == "station" else "")
                x = t.positions_mm
                d = max(float(np.max(np.abs(np.asarray(t.error_fwd_um) - dt.correction_um(x, 1)))),
                        float(np.max(np.abs(np.asarray(t.error_rev_um) - dt.correction_um(x, -1)))))
                diff = f"{d:.3f}"
            rows.append((str(leg), f"{t.start_mm:+.3f}", f"{t.step_mm:g}", str(t.point_count),
                         f"{min(t.error_fwd_um):+.3f}..{max(t.error_fwd_um):+.3f}",
                         f"{min(t.error_rev_um):+.3f}..{max(t.error_rev_um):+.3f}", bank, diff))
        order = fit_columns(self, [(self.COLUMNS, None), self.NARROW], rows, self.app.size.width - 2)
        for cells in rows:
            self.add_row(*(cells[i] for i in order), key=cells[0])


class TablePlots(Horizontal):
    """The selected leg's table (new and active, both directions) and new minus active."""

    def compose(self):
        yield XYPlot("table", "position mm", "error µm", id="comp-plot")
        yield XYPlot("new − active", "position mm", "µm", id="comp-diff-plot")

    def show(self, leg: int | None, table, drive: DriveTable | None) -> None:
        plot = self.query_one("#comp-plot", XYPlot)
        diff = self.query_one("#comp-diff-plot", XYPlot)
        if leg is None or table is None:
            plot.show([], title="table (none yet)")
            diff.show([], title="new − active (none yet)")
            return
        t = table.legs[leg]
        x = t.positions_mm
        series = [("new fwd (+1)", x, t.error_fwd_um, "line"), ("new rev (−1)", x, t.error_rev_um, "line")]
        dseries = []
        fwd_active = drive.correction_um(x, 1) if drive is not None else None
        if fwd_active is not None:
            rev_active = drive.correction_um(x, -1)
            series += [("active fwd", x, fwd_active, "line"), ("active rev", x, rev_active, "line")]
            dseries = [("fwd", x, np.asarray(t.error_fwd_um) - fwd_active, "line"),
                       ("rev", x, np.asarray(t.error_rev_um) - rev_active, "line")]
        plot.show(series, title=f"leg {leg}: table, {t.point_count} points every {t.step_mm:g} mm")
        diff.show(dseries, title=f"leg {leg}: new − active" + ("" if dseries else " (drive not read: g)"))


class AuditTail(Static):
    """The newest entries of the audit log (newest last), one line each."""

    def show(self, entries: list, error: str = "", hide_time: bool = False, width: int = 112) -> None:
        if error:
            self.update(f"audit log: [red]{error}[/red]")
            return
        if not entries:
            self.update("audit log: no entries yet")
            return
        lines = ["audit log (newest last):"]
        for e in entries:
            when = "" if hide_time else f"{e.time_utc[:19]} "
            head = f"  {when}{e.action} leg {e.leg} {e.outcome}: "
            message = e.message if len(head) + len(e.message) <= width else e.message[:width - 3 - len(head)] + "…"
            lines.append(f"{head}{message}".replace("[", "\\["))
        self.update("\n".join(lines))
