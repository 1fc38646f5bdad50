"""Station-side compensation: the station applies a leg's table to every target it commands.

For a leg whose compensation target is `station` (config `[compensation]`, docs/compensation.md)
`station/services/wiring.py` wraps the leg's drive in `StationCompensatedAxis`. The wrapper is a
`ServoAxis` like any drive, and holds two table banks, the active bank and the enable flag just
as a drive with a table does, so push, verify, rollback and the audit log (procedures/compensation/push.py,
procedures/compensation/verify.py) run through it unchanged. It lives in drivers/ because it *is* a driver
(a decorator of another one) that procedures must not be able to tell from a drive.

Sign convention (the same as the drive's, drivers/sim/drive_server.py `_start_move`): a table
holds the predicted error e(x, d) of the leg, measured minus commanded, um, approaching x in
direction d. The drive subtracts it; so does the station:

    commanded_mm = target_mm - e(target_mm, d) * 1e-3      (correction_um = -e)

where d = +1 when `target_mm` is above the previous target, -1 below it, unchanged when equal
(the drive's rule), and e is interpolated linearly between table points, held at the end
values outside the table, 0 when the table is empty or switched off.

Positions read back: a drive applying its own table reports its position actual in commanded
space, i.e. the raw position plus the correction of the current move, so that a leg at rest on
its target reads the target. The wrapper does the same: `status().position_mm` = the drive's
position + correction_um * 1e-3 of the move under way (or the last one). Following error and
load are the drive's, unchanged.

Soft limits apply to both: the target (leg coordinates) and the compensated command sent to
the drive must lie within the drive's soft limits, else SoftLimitError before any motion.

The tables live in one JSON file for all legs (`StationTableStore`, default
<recordings_dir>/station-tables.json), rewritten atomically (temp file, fsync, os.replace,
fsync of the folder) under an exclusive lock on every change, like a drive's EEPROM: a crash
mid-write leaves the previous file, so the previous table stays active. A write goes to the
inactive bank, the switch is a separate write, as on a drive.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import math
import os
import threading
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from drivers.atomic import write_files_atomic
from drivers.errors import DriverError, SoftLimitError, TableError
from drivers.interfaces import DriveLimits, DriveStatus, ServoAxis, TableBank, TableSpec, table_sha256

STORE_FORMAT = "station-compensation-tables"
STORE_VERSION = 1
BANKS = 2

TARGET = "station"
"""The compensation target this wrapper implements (`compensation_target` attribute)."""


class StoreError(DriverError):
    """The station's table store cannot be read or written."""

    hint = ("The previously active table is still active. Restore the file from a copy, or move it away "
            "to start with empty tables (the audit log holds every pushed table and its backup).")


def station_table_spec(path: str | Path) -> TableSpec:
    """What the station's store holds per leg: two banks, entries to 1 nm, the same largest
    correction as the default drive (a leg needing more is broken, not one to compensate)."""
    return TableSpec(max_points=4096, max_correction_um=300.0, entry_resolution_um=0.001, min_step_mm=0.001,
                     banks=BANKS, holder=f"the station's table store ({path})")


_sha256 = table_sha256  # the same identity as the audit log and the drive path


EMPTY = TableBank(0.0, 0.0, (), ())


@dataclass(frozen=True)
class LegTables:
    """One leg's state in the store: both banks, which is active, whether it is applied."""

    banks: tuple[TableBank, ...] = (EMPTY, EMPTY)
    active_bank: int = 0
    enabled: bool = True

    @property
    def active(self) -> TableBank:
        return self.banks[self.active_bank]


def _bank_json(table: TableBank) -> dict[str, Any]:
    return {"start_mm": float(table.start_mm), "spacing_mm": float(table.spacing_mm),
            "error_fwd_um": [float(v) for v in table.error_fwd_um],
            "error_rev_um": [float(v) for v in table.error_rev_um], "sha256": _sha256(table)}


class StationTableStore:
    """The JSON file of every station-compensated leg's tables (format in docs/compensation.md).

    Reads need no lock (the file is only ever replaced whole); changes take an exclusive
    `flock` on `<path>.lock`, re-read the file, change one leg and replace the file atomically,
    so two processes pushing different legs never lose each other's change."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    # -- reading ---------------------------------------------------------------------------------
    def stamp(self) -> tuple[int, int, int] | None:
        """(inode, mtime_ns, size) of the file, None when it does not exist: a change detector."""
        try:
            s = os.stat(self.path)
        except FileNotFoundError:
            return None
        return (s.st_ino, s.st_mtime_ns, s.st_size)

    def read(self) -> dict[int, LegTables]:
        """Every leg in the store; {} when the file does not exist. StoreError naming the file and
        the key when it is damaged."""
        try:
            text = self.path.read_text()
        except FileNotFoundError:
            return {}
        except OSError as exc:
            raise StoreError(f"{self.path}: cannot read the station's table store ({exc.strerror or exc}).") from None
        except UnicodeDecodeError as exc:
            raise StoreError(f"{self.path}: not UTF-8 text (byte {exc.start}); the station's table store is damaged.") from None
        try:
            doc = json.loads(text)
        except ValueError as exc:
            raise StoreError(f"{self.path}: not valid JSON ({exc}); the station's table store is damaged.") from None
        if not isinstance(doc, dict) or doc.get("format") != STORE_FORMAT:
            raise StoreError(f"{self.path}: key format: expected {STORE_FORMAT!r}; this is not a station table store.")
        if doc.get("version") != STORE_VERSION:
            raise StoreError(f"{self.path}: key version: {doc.get('version')!r} is not supported (this station reads "
                             f"version {STORE_VERSION}).")
        legs = doc.get("legs")
        if not isinstance(legs, dict):
            raise StoreError(f"{self.path}: key legs: must be an object of leg number -> tables.")
        return {self._leg_number(k): self._leg(k, v) for k, v in legs.items()}

    def leg(self, leg: int) -> LegTables:
        return self.read().get(int(leg), LegTables())

    def _leg_number(self, key: str) -> int:
        try:
            n = int(key)
        except ValueError:
            n = 0
        if n < 1:
            raise StoreError(f"{self.path}: key legs.{key}: not a leg number (1, 2, ...).")
        return n

    def _leg(self, key: str, v: Any) -> LegTables:
        where = f"{self.path}: key legs.{key}"
        if not isinstance(v, dict):
            raise StoreError(f"{where}: must be an object with banks, active_bank, enabled.")
        banks = v.get("banks")
        if not isinstance(banks, list) or len(banks) != BANKS:
            raise StoreError(f"{where}.banks: must be a list of {BANKS} tables.")
        active, enabled = v.get("active_bank"), v.get("enabled")
        if active not in range(BANKS) or isinstance(active, bool):
            raise StoreError(f"{where}.active_bank: {active!r} is not a bank number 0..{BANKS - 1}.")
        if not isinstance(enabled, bool):
            raise StoreError(f"{where}.enabled: {enabled!r} is not true or false.")
        return LegTables(tuple(self._bank(f"{where}.banks[{i}]", b) for i, b in enumerate(banks)), active, enabled)

    @staticmethod
    def _bank(where: str, b: Any) -> TableBank:
        try:
            fwd = tuple(float(x) for x in b["error_fwd_um"])
            rev = tuple(float(x) for x in b["error_rev_um"])
            table = TableBank(float(b["start_mm"]), float(b["spacing_mm"]), fwd, rev)
            sha = b["sha256"]
        except (KeyError, TypeError, ValueError, OverflowError) as exc:  # Overflow: a JSON integer beyond any float
            raise StoreError(f"{where}: malformed table ({exc!r}): needs start_mm, spacing_mm, error_fwd_um, "
                             "error_rev_um, sha256.") from None
        if len(fwd) != len(rev) or not all(math.isfinite(x) for x in fwd + rev + (table.start_mm, table.spacing_mm)):
            raise StoreError(f"{where}: unequal or non-finite entries.")
        if _sha256(table) != sha:
            raise StoreError(f"{where}.sha256: the entries do not match their recorded hash (the file was altered "
                             "or damaged); the table is not used.")
        return table

    # -- changing --------------------------------------------------------------------------------
    @contextlib.contextmanager
    def _locked(self):
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(str(self.path) + ".lock", os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            yield
        finally:
            os.close(fd)  # releases the lock

    def update(self, leg: int, change, drive: str = "") -> LegTables:
        """Replace leg `leg`'s state by `change(current)` (a LegTables) in one atomic file write."""
        try:
            with self._locked():
                legs = self.read()
                new = change(legs.get(int(leg), LegTables()))
                legs[int(leg)] = new
                self._write(legs, {int(leg): drive})
                return new
        except OSError as exc:
            raise StoreError(f"{self.path}: cannot write the station's table store ({exc.strerror or exc}).") from None

    def _write(self, legs: dict[int, LegTables], drives: dict[int, str]) -> None:
        old = self._raw_legs()
        now = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
        doc_legs: dict[str, Any] = {}
        for n in sorted(legs):
            t = legs[n]
            entry = {"active_bank": t.active_bank, "enabled": t.enabled, "banks": [_bank_json(b) for b in t.banks]}
            prev = old.get(str(n), {}) if isinstance(old.get(str(n)), dict) else {}
            entry["drive"] = drives.get(n) or prev.get("drive", "")
            entry["updated_utc"] = now if n in drives else prev.get("updated_utc", now)
            doc_legs[str(n)] = entry
        doc = {"format": STORE_FORMAT, "version": STORE_VERSION, "legs": doc_legs}
        data = (json.dumps(doc, indent=1) + "\n").encode()
        write_files_atomic({self.path: data})  # the rename itself survives a power cut

    def _raw_legs(self) -> dict[str, Any]:
        try:
            return json.loads(self.path.read_text()).get("legs", {})
        except (OSError, ValueError, AttributeError):
            return {}


def correction_um(table: TableBank, target_mm: float, direction: int) -> float:
    """The table's predicted error at `target_mm` approaching in `direction`, um: linear
    interpolation, end values held outside the table, 0 for an empty table (the drive's rule)."""
    vals = table.error_fwd_um if direction > 0 else table.error_rev_um
    n = len(vals)
    if n == 0:
        return 0.0
    if n == 1 or not table.spacing_mm > 0:
        return float(vals[0])
    u = min(max((target_mm - table.start_mm) / table.spacing_mm, 0.0), n - 1.0)
    i = min(int(u), n - 2)
    f = u - i
    return vals[i] * (1 - f) + vals[i + 1] * f


class StationCompensatedAxis:
    """A `ServoAxis` whose table the station applies (module docstring): `inner` is the leg's
    drive, which must not apply a table of its own (`check_drive_table`)."""

    compensation_target = TARGET

    def __init__(self, inner: ServoAxis, store: StationTableStore) -> None:
        self.inner = inner
        self.leg = inner.leg
        self.store = store
        self.spec = station_table_spec(store.path)
        self._lock = threading.Lock()
        self._stamp: Any = object()  # never equal: the first move reads the store
        self._tables = LegTables()
        self._last_target_mm: float | None = None
        self._direction = 1
        self._corr_um = 0.0  # correction of the move under way or the last one (the drive's corr_um)

    def __repr__(self) -> str:
        return f"StationCompensatedAxis(leg {self.leg}, {self.store.path}, {self.inner!r})"

    # -- the drive's table must stay out of it ---------------------------------------------------
    def check_drive_table(self) -> None:
        """Refuse (TableError) a drive that applies a non-empty table of its own: with the station's
        table on top, the leg would be corrected twice."""
        if self.inner.table_spec() is None:
            return
        st = self.inner.status()
        if not st.table_enabled:
            return
        own = self.inner.read_table(st.active_bank)
        if own.point_count:
            raise TableError(
                f"leg {self.leg}: compensation target is station, but the drive applies its own table (bank "
                f"{st.active_bank}, {own.point_count} points): the leg would be corrected twice. Roll the drive's table "
                "back (`station rollback` with target drive) or switch its table off, or set the leg's target to "
                "drive in [compensation].", hint="Nothing moved.")

    # -- tables (what push, verify and rollback use) ---------------------------------------------
    def _state(self) -> LegTables:
        """The leg's state as stored now (re-read when the file changed since last time)."""
        stamp = self.store.stamp()
        if stamp != self._stamp:
            self._tables = self.store.leg(self.leg)
            self._stamp = stamp
        return self._tables

    def table_spec(self) -> TableSpec:
        return self.spec

    def active_bank(self) -> int:
        with self._lock:
            return self._state().active_bank

    def _check_bank(self, bank: int) -> None:
        if bank not in range(BANKS):
            raise TableError(f"leg {self.leg}: table bank {bank!r} does not exist (banks are 0..{BANKS - 1}).", hint="")

    def read_table(self, bank: int) -> TableBank:
        self._check_bank(bank)
        with self._lock:
            return self._state().banks[bank]

    def write_table(self, bank: int, table: TableBank) -> None:
        """Store `table` (as the spec quantises it) in the inactive `bank`; the active one is
        refused, as a drive refuses it. Does not activate."""
        self._check_bank(bank)
        self.spec.check(table, f"leg {self.leg}", min_points=0)
        q = self.spec.quantize(table)

        def change(t: LegTables) -> LegTables:
            if bank == t.active_bank:
                raise TableError(f"leg {self.leg}: bank {bank} is the active table; write bank {1 - bank} and activate it.")
            banks = list(t.banks)
            banks[bank] = q
            return LegTables(tuple(banks), t.active_bank, t.enabled)

        self._update(change)

    def activate_table(self, bank: int) -> None:
        """Make `bank` the active table (one store write); refused while the axis moves."""
        self._check_bank(bank)
        if self.inner.status().moving:
            raise TableError(f"leg {self.leg}: the axis is moving; the station switches tables only at standstill.")
        self._update(lambda t: LegTables(t.banks, bank, t.enabled))

    def set_table_enabled(self, on: bool) -> None:
        """Switch applying the active table on or off."""
        self._update(lambda t: LegTables(t.banks, t.active_bank, bool(on)))

    def _update(self, change) -> None:
        with self._lock:
            self._tables = self.store.update(self.leg, change, drive=self._identity())
            self._stamp = self.store.stamp()

    def _identity(self) -> str:
        try:
            return self.inner.identity()
        except DriverError:
            return ""

    # -- motion ----------------------------------------------------------------------------------
    def identity(self) -> str:
        return self.inner.identity()

    def drive_identity(self) -> dict:
        return self.inner.drive_identity()

    def limits(self) -> DriveLimits:
        return self.inner.limits()

    def fault_text(self, code: int) -> str:
        return self.inner.fault_text(code)

    def _report(self, st: DriveStatus, corr_um: float) -> DriveStatus:
        t = self._tables
        return DriveStatus(st.state, st.fault, st.fault_code, st.moving, st.target_reached,
                           st.position_mm + corr_um * 1e-3, st.following_error_um, st.load_n,
                           t.active_bank, t.enabled)

    def status(self) -> DriveStatus:
        st = self.inner.status()
        with self._lock:
            self._state()
            return self._report(st, self._corr_um)

    def enable(self) -> None:
        self.inner.enable()

    def disable(self) -> None:
        self.inner.disable()

    def reset_fault(self) -> None:
        self.inner.reset_fault()

    def stop(self) -> None:
        # like the drive's halt: the next move takes its direction from where the leg stopped
        self._last_target_mm = None
        self.inner.stop()

    def command_for(self, target_mm: float) -> tuple[float, float, int]:
        """(commanded_mm, correction_um, direction) for a move to `target_mm` from the last target:
        commanded_mm = target_mm - e(target_mm, direction) * 1e-3. Changes nothing."""
        with self._lock:
            t = self._state()
            last = self._last_target_mm
            if last is None:
                last = self.inner.status().position_mm + self._corr_um * 1e-3
            direction = self._direction if target_mm == last else (1 if target_mm > last else -1)
            e_um = correction_um(t.active, target_mm, direction) if t.enabled else 0.0
        return target_mm - e_um * 1e-3, e_um, direction

    def move_to(self, target_mm: float, timeout_s: float | None = None,
                velocity_mm_s: float | None = None) -> DriveStatus:
        lim = self.inner.limits()
        if not (isinstance(target_mm, (int, float)) and math.isfinite(target_mm)):
            raise SoftLimitError(f"leg {self.leg}: target {target_mm!r} is not a finite position in mm; nothing moved.")
        if not lim.min_mm <= target_mm <= lim.max_mm:
            raise SoftLimitError(f"leg {self.leg}: target {target_mm:.4f} mm is outside the soft limits "
                                 f"{lim.min_mm:.3f} .. {lim.max_mm:.3f} mm reported by the drive; nothing moved.")
        commanded, e_um, direction = self.command_for(target_mm)
        if not lim.min_mm <= commanded <= lim.max_mm:
            raise SoftLimitError(f"leg {self.leg}: target {target_mm:.4f} mm compensated by the station's table "
                                 f"({-e_um:+.3f} um) is {commanded:.6f} mm, outside the soft limits {lim.min_mm:.3f} .. "
                                 f"{lim.max_mm:.3f} mm; nothing moved.")
        with self._lock:
            self._last_target_mm = float(target_mm)
            self._direction = direction
            self._corr_um = e_um
        try:
            st = self.inner.move_to(commanded, timeout_s=timeout_s, velocity_mm_s=velocity_mm_s)
        except BaseException:
            # stopped short (fault, timeout, quick stop): the next direction from where the leg is
            self._last_target_mm = None
            raise
        with self._lock:
            return self._report(st, e_um)

    def close(self) -> None:
        self.inner.close()
