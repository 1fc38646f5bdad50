"""Crash-safe writer of HDF5 session files (layout in schema.py and docs/session-schema.md).

Durability: `append_point` writes the point's row to the journal beside the file (journal.py:
one os.write, in the kernel's page cache when it returns) before it returns, so every point the
caller acknowledges survives a kill of the process (SIGKILL, crash, Ctrl-C); /points of the HDF5
file grows in batches (every FLUSH_ROWS points or FLUSH_S seconds, and before a fault, `flush`,
`finish` and `close`). Readers of a session cut short add the journal's rows (reader.py), a clean
close removes the journal. Power loss needs `fsync=True` as well (the journal is fsynced per point).

Live reading: the file is in SWMR mode while it is written, so another process can open it
with `h5py.File(path, "r", swmr=True)` (or `reader.LiveReader`) and watch it grow.

Why the file is built at a temporary path and renamed: a file at the final path is always a
complete session skeleton (metadata written), and `resume` can rebuild a killed file without
ever risking what is already recorded.
"""

from __future__ import annotations

import fcntl
import json
import os
import struct
import time
from collections.abc import Mapping
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from procedures.vocabulary import InputError, SchemaError
from procedures.io.recording.journal import Journal
from procedures.io.recording.stage import STAGES, session_stage
from procedures.io.recording.schema import (
    FAULT_DTYPE,
    FAULT_UNITS,
    FAULTS_CHUNK_ROWS,
    POINT_DTYPE,
    POINT_REQUIRED_KEYS,
    POINT_UNITS,
    POINTS_CHUNK_ROWS,
    SCHEMA_VERSION,
    PointRecord,
    UNWRITTEN_INDEX,
    schema_major,
)
from procedures.vocabulary import Outcome

# v1.10 file format: needed for SWMR, and still readable by HDF5 1.10 tools (Debian's h5dump).
LIBVER = ("v110", "v110")

FLUSH_ROWS = 64
"""Points written to /points at once (their journal rows make them durable before that)."""
FLUSH_S = 0.5
"""... or sooner, when the oldest unwritten point is this old (a live HDF5 reader's lag)."""


def utc_now() -> str:
    """Current UTC time as ISO 8601 text with milliseconds, e.g. 2026-05-09T07:35:25.123+00:00."""
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (Path, os.PathLike)):
        return str(obj)
    if isinstance(obj, (set, frozenset)):
        return sorted(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def to_json_text(name: str, value: Any) -> str:
    """`value` as JSON text for the /meta attribute `name` (InputError if it cannot be)."""
    try:
        return json.dumps(value, sort_keys=True, default=_json_default, allow_nan=True)
    except (TypeError, ValueError) as exc:
        raise InputError(f"session metadata '{name}' cannot be stored as JSON: {exc}") from exc


def _blank(dtype: np.dtype) -> np.ndarray:
    """One row of `dtype`: floats NaN (unknown), integers 0, index = UNWRITTEN_INDEX."""
    row = np.zeros(1, dtype)
    for name in dtype.names:
        if dtype[name].kind == "f":
            row[name] = np.nan
    if "index" in dtype.names:
        row["index"] = UNWRITTEN_INDEX
    return row


_POINT_BLANK = _blank(POINT_DTYPE)
_FAULT_BLANK = _blank(FAULT_DTYPE)
_POINT_FILL = _POINT_BLANK[0].copy()
_FAULT_FILL = _FAULT_BLANK[0].copy()


_POINT_DEFAULTS = tuple(_POINT_BLANK[0].tolist())
_POINT_POS = {name: i for i, name in enumerate(POINT_DTYPE.names)}
# the field names from the first up to each one that completes the required keys
_POINT_PREFIXES = frozenset(POINT_DTYPE.names[:n] for n in range(1, len(POINT_DTYPE.names) + 1)
                            if set(POINT_REQUIRED_KEYS) <= set(POINT_DTYPE.names[:n]))


def _point_values(record: PointRecord | Mapping[str, Any]) -> list[Any] | tuple:
    """The POINT_DTYPE field values of a record (a PointRecord, or a dict keyed by field names),
    in field order, defaults filled in and checked (see point_row)."""
    if type(record) is PointRecord:  # a procedure's record: its fields are the row
        values = record.to_row()
        if values[0] < 0 or values[3] not in (1, -1) or values[1] < 1 or values[2] < 1:
            _check_point(np.array([values], POINT_DTYPE))  # raises with the message
        return values
    keys = tuple(record)
    if keys in _POINT_PREFIXES:  # the fields in file order (a sweep's records): no lookup per key
        values = [*record.values(), *_POINT_DEFAULTS[len(keys):]]
    else:
        missing = [k for k in POINT_REQUIRED_KEYS if k not in record]
        if missing:
            raise SchemaError(f"point record lacks required field(s) {', '.join(missing)}")
        values = list(_POINT_DEFAULTS)
        for key, value in record.items():
            pos = _POINT_POS.get(key)
            if pos is None:
                raise SchemaError(
                    f"point record has unknown field '{key}'; known fields: {', '.join(POINT_DTYPE.names)}"
                )
            values[pos] = value
    index, leg, run, direction = (values[_POINT_POS[k]] for k in ("index", "leg", "run", "direction"))
    if index < 0 or direction not in (1, -1) or leg < 1 or run < 1:
        _check_point(np.array([tuple(values)], POINT_DTYPE))  # raises with the message
    return values


def point_row(record: PointRecord | Mapping[str, Any] | np.void) -> np.ndarray:
    """A POINT_DTYPE array of one row from a PointRecord, or a dict (or numpy record) keyed by
    field names.

    Keys in POINT_REQUIRED_KEYS must be present; absent float fields are NaN (unknown), absent
    `flags` is 0. An unknown key raises SchemaError (a typo would lose data silently).
    """
    if isinstance(record, np.void) and record.dtype.names:
        if record.dtype == POINT_DTYPE:
            row = np.empty(1, POINT_DTYPE)
            row[0] = record
            _check_point(row)
            return row
        record = {n: record[n] for n in record.dtype.names}
    if not isinstance(record, Mapping):
        raise TypeError(f"a point record must be a PointRecord, a dict or a numpy record, not {type(record).__name__}")
    # one tuple -> one row: several times faster than assigning the fields one by one
    return np.array([tuple(_point_values(record))], POINT_DTYPE)


_STRUCT_CODE = {"<i8": "q", "<i2": "h", "<i4": "i", "|i1": "b", "<f8": "d", "<f4": "f", "<u4": "I"}
_POINT_STRUCT = struct.Struct("<" + "".join(_STRUCT_CODE[POINT_DTYPE[n].str] for n in POINT_DTYPE.names))
assert _POINT_STRUCT.size == POINT_DTYPE.itemsize  # packed, no padding: the same bytes as numpy's row


def point_bytes(record: PointRecord | Mapping[str, Any] | np.void) -> tuple[int, bytes]:
    """(index, the bytes of `point_row(record)`): a record of plain numbers is packed with one
    struct call, a quarter of the time of a numpy row (once per point: the recorder's main
    cost); anything struct does not take as numpy does (a float in an integer field, a text
    number, a value out of a field's range) goes the numpy way, with its conversions and errors."""
    if isinstance(record, Mapping):
        values = _point_values(record)
        try:
            return int(values[0]), _POINT_STRUCT.pack(*values)
        except (struct.error, OverflowError, TypeError):
            row = np.array([tuple(values)], POINT_DTYPE)
    else:
        row = point_row(record)
    return int(row[0]["index"]), row.tobytes()


class _IndexSet:
    """The plan indices in a file: one bit each below 2**24 (16 M points), a set above. A set of
    ints costs about 60 bytes a point, 12 MB over a day-long session of 200 000 points, which a
    soak sees as the station's memory growing (bench/bench_soak.py); the bitmap holds 25 kB."""

    _BITMAP_LIMIT = 1 << 24

    def __init__(self, indices=()) -> None:
        self._bits = bytearray()
        self._large: set[int] = set()
        self.update(indices)

    def __contains__(self, i: int) -> bool:
        i = int(i)
        if 0 <= i < self._BITMAP_LIMIT:
            return (i >> 3) < len(self._bits) and bool(self._bits[i >> 3] & (1 << (i & 7)))
        return i in self._large

    def add(self, i: int) -> None:
        i = int(i)
        if not 0 <= i < self._BITMAP_LIMIT:
            self._large.add(i)
            return
        byte = i >> 3
        if byte >= len(self._bits):
            self._bits.extend(bytes(max(byte + 1 - len(self._bits), len(self._bits))))  # doubling
        self._bits[byte] |= 1 << (i & 7)

    def update(self, indices) -> None:
        for i in indices:
            self.add(i)

    def intersection(self, indices) -> set[int]:
        return {int(i) for i in indices if int(i) in self}

    def __iter__(self):
        for byte, value in enumerate(self._bits):
            if value:
                yield from (byte * 8 + b for b in range(8) if value & (1 << b))
        yield from sorted(self._large)

    def __len__(self) -> int:
        return sum(bin(v).count("1") for v in self._bits) + len(self._large)


def _check_point(rows: np.ndarray) -> None:
    """InputError for the first row with index < 0, direction not +1/-1, or leg/run < 1."""
    bad = (rows["index"] < 0) | ((rows["direction"] != 1) & (rows["direction"] != -1)) | (rows["leg"] < 1) | (
        rows["run"] < 1
    )
    if not bad.any():
        return
    r = rows[int(np.argmax(bad))]
    index, leg, run, direction = int(r["index"]), int(r["leg"]), int(r["run"]), int(r["direction"])
    if index < 0:
        raise InputError(f"point index must be >= 0, got {index}")
    if direction not in (1, -1):
        raise InputError(f"point {index}: direction must be +1 or -1, got {direction}")
    raise InputError(f"point {index}: leg and run are 1-based, got leg {leg} run {run}")


def fault_row(record: Mapping[str, Any] | np.void) -> np.ndarray:
    """A FAULT_DTYPE array of one row from a dict keyed by FAULT_DTYPE field names.

    `kind` and `message` may be str (UTF-8, truncated to the field size); `gave_up` may be bool.
    Absent fields: numbers 0 / NaN, strings empty; `index` is required.
    """
    if isinstance(record, np.void) and record.dtype.names:
        record = {n: record[n] for n in record.dtype.names}
    if "index" not in record:
        raise SchemaError("fault record lacks required field index")
    row = _FAULT_BLANK.copy()
    for key, value in record.items():
        if key not in FAULT_UNITS:
            raise SchemaError(f"fault record has unknown field '{key}'; known fields: {', '.join(FAULT_DTYPE.names)}")
        if FAULT_DTYPE[key].kind == "S":
            size = FAULT_DTYPE[key].itemsize
            raw = value if isinstance(value, bytes) else str(value).encode("utf-8")
            # cut at a character boundary so the stored text stays valid UTF-8
            value = raw[:size].decode("utf-8", "ignore").encode("utf-8")
        row[key] = value
    return row


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _temp_path(path: Path, purpose: str) -> Path:
    return path.with_name(f".{path.name}.{purpose}-{os.getpid()}.tmp")


def _write_rows(ds: h5py.Dataset, rows: np.ndarray) -> None:
    """Append `rows` to the 1-D dataset `ds` (grow, then write)."""
    n0 = ds.shape[0]
    ds.id.set_extent((n0 + len(rows),))
    if len(rows):
        ds[n0:] = rows


def build_session_file(
    path: Path,
    root_attrs: Mapping[str, str],
    meta_attrs: Mapping[str, str],
    points: np.ndarray | None = None,
    faults: np.ndarray | None = None,
    copy_from: h5py.File | None = None,
) -> None:
    """Write a complete, closed session file at `path` (a temporary path: callers rename it).

    `root_attrs` / `meta_attrs` are stored as given (this station writes strings). Objects of `copy_from` other than
    /points, /faults and /meta (e.g. groups added by a newer minor version) are copied as is.
    The file is fsynced before this returns.
    """
    with h5py.File(path, "w", libver=LIBVER) as f:
        for key, value in root_attrs.items():
            f.attrs[key] = value
        meta = f.create_group("meta")
        for key, value in meta_attrs.items():
            meta.attrs[key] = value
        pds = f.create_dataset(
            "points", shape=(0,), maxshape=(None,), dtype=POINT_DTYPE,
            chunks=(POINTS_CHUNK_ROWS,), fillvalue=_POINT_FILL,
        )
        for name, unit in POINT_UNITS.items():
            pds.attrs[f"units_{name}"] = unit
        fds = f.create_dataset(
            "faults", shape=(0,), maxshape=(None,), dtype=FAULT_DTYPE,
            chunks=(FAULTS_CHUNK_ROWS,), fillvalue=_FAULT_FILL,
        )
        for name, unit in FAULT_UNITS.items():
            fds.attrs[f"units_{name}"] = unit
        if points is not None:
            _write_rows(pds, np.asarray(points, POINT_DTYPE))
        if faults is not None:
            _write_rows(fds, np.asarray(faults, FAULT_DTYPE))
        if copy_from is not None:
            for name in copy_from:
                if name not in ("points", "faults", "meta"):
                    copy_from.copy(copy_from[name], f, name)
    _fsync_path(path)


def _replace(tmp: Path, path: Path) -> None:
    os.replace(tmp, path)
    _fsync_path(path.parent)  # make the rename itself durable


class SessionLock:
    """An exclusive advisory lock on a hidden file beside the session (`.NAME.lock`).

    HDF5 drops its own file lock once a file is in SWMR mode, so without this a second
    process could resume (rebuild and rename) a session another process is still appending
    to, and the points of the first would go to a file that no longer has a name. The kernel
    releases the lock when its holder dies, so a killed session can be resumed at once.
    """

    def __init__(self, path: Path) -> None:
        self.lock_path = path.with_name(f".{path.name}.lock")
        fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 32).decode("ascii", "replace").strip() or "?"
            os.close(fd)
            raise InputError(
                f"{path}: another station process (pid {holder}) is writing this session; "
                "wait for it to finish or stop it first"
            ) from None
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
        self._fd: int | None = fd

    def release(self) -> None:
        fd, self._fd = self._fd, None  # first: a release cut short is not repeated on a closed fd
        if fd is None:
            return
        try:
            self.lock_path.unlink(missing_ok=True)
        finally:
            os.close(fd)


class SessionWriter:
    """Appends points and faults to one session file; see the module docstring.

    Create with `SessionWriter.create(...)` or continue a cut-short file with
    `SessionWriter.resume(path)`. Use as a context manager: leaving the block closes the file;
    on KeyboardInterrupt it is finished as "aborted", on another exception as "failed"; on a
    normal exit without `finish` the outcome stays unset (read back as "incomplete").
    Single-threaded: call it from one thread.
    """

    def __init__(self, path: Path, points_index: np.ndarray, faults_written: int, fsync: bool,
                 lock: SessionLock) -> None:
        # use create() or resume()
        self.path = path
        self._lock = lock
        self._fsync = fsync
        self._indices = _IndexSet(int(i) for i in points_index)
        self._points_written = len(points_index)
        self._faults_written = faults_written
        self._finished_outcome: Outcome | None = None
        # no chunk cache: every row is flushed at once anyway, and the cache grew the process by
        # about 10 MB over a long session (bench/bench_soak.py); without it an append is faster
        self._f = h5py.File(path, "a", libver=LIBVER, rdcc_nbytes=0)
        try:
            self._pds = self._f["points"]
            self._fds = self._f["faults"]
            if self._pds.dtype != POINT_DTYPE or self._fds.dtype != FAULT_DTYPE:
                raise SchemaError(f"{path}: /points or /faults does not have this station's row layout")
            self._f.swmr_mode = True
        except BaseException:
            self._f.close()
            lock.release()
            raise
        # Pass the file's own types to H5Dwrite: h5py would otherwise rebuild the compound type
        # on every call (about 0.4 ms per row).
        self._ptype = self._pds.id.get_type()
        self._ftype = self._fds.id.get_type()
        self._pending: list[bytes] = []  # acknowledged rows (in the journal) not yet in /points
        self._pending_since = 0.0
        try:
            self._journal: Journal | None = Journal(path, str(self._f.attrs.get("session_id", "")), fsync)
        except BaseException:
            self._f.close()
            lock.release()
            raise

    # -- opening ---------------------------------------------------------------------------

    @classmethod
    def create(
        cls,
        path: str | os.PathLike,
        *,
        session_id: str,
        operator: str,
        rig: str,
        plan: dict,
        station_config: dict,
        devices: dict,
        software_version: str,
        started_utc: str | None = None,
        fsync: bool = False,
        overwrite: bool = False,
        identity: dict | None = None,
        stage: str | None = None,
    ) -> "SessionWriter":
        """Create a new session file at `path` and return a writer in SWMR mode.

        `rig` is "sim", "live", "replay" or "import". `plan`, `station_config`, `devices` are
        JSON-able dicts stored as JSON text in /meta, and so is `identity` (the
        `SessionIdentity.to_json()` object, procedures/io/recording/identity.py) when given. Refuses an existing `path` unless
        `overwrite` (a finished six-hour session must not vanish under a repeated command).
        `stage` (root attribute, schema 1.2): the stage of the leg's life the session records
        (procedures/io/recording/stage.py); None: derived from `plan`, `devices` and `rig`.
        """
        path = Path(path)
        if path.exists() and not overwrite:
            raise InputError(
                f"{path}: file exists; choose another --out, or resume the session it holds"
            )
        if not path.parent.is_dir():
            raise InputError(f"{path}: directory {path.parent} does not exist")
        root = {
            "schema_version": SCHEMA_VERSION,
            "software_version": str(software_version),
            "session_id": str(session_id),
            "operator": str(operator),
            "rig": str(rig),
            "started_utc": started_utc or utc_now(),
            "ended_utc": "",
            "outcome": "",
            "resumed_utc": "[]",
            # from what the session is created with (plan kind, tables active at the start, rig):
            # kept across resumes, since a resume copies the root attributes
            "stage": stage if stage is not None else session_stage(plan, devices, rig),
        }
        if root["stage"] not in STAGES:
            raise InputError(f"{path}: unknown stage {root['stage']!r} (one of {', '.join(STAGES)})")
        meta = {
            "plan": to_json_text("plan", plan),
            "station_config": to_json_text("station_config", station_config),
            "devices": to_json_text("devices", devices),
        }
        if identity is not None:
            meta["identity"] = to_json_text("identity", identity)
        lock = SessionLock(path)
        tmp = _temp_path(path, "new")
        try:
            if path.exists() and not overwrite:  # again, now that no other writer can race us
                raise InputError(f"{path}: file exists; choose another --out, or resume the session it holds")
            build_session_file(tmp, root, meta)
            _replace(tmp, path)
        except BaseException:
            lock.release()
            raise
        finally:
            tmp.unlink(missing_ok=True)
        return cls(path, np.empty(0, np.int64), 0, fsync, lock)

    @classmethod
    def resume(cls, path: str | os.PathLike, *, fsync: bool = False, resumed_utc: str | None = None) -> "SessionWriter":
        """Reopen a session cut short (killed, Ctrl-C, failed) to append the remaining points.

        A killed SWMR file cannot be reopened for writing, so the session is rebuilt: every
        readable row and all metadata are written to a temporary file beside it, fsynced, and
        renamed over the original (a crash meanwhile leaves the original untouched). The outcome
        and end time are cleared and the resume time is appended to the root `resumed_utc`.
        `indices_written()` then tells the caller which plan points to skip.
        """
        from procedures.io.recording.reader import open_h5, read_session  # reader never imports writer

        path = Path(path)
        read_session(path)  # clear errors (missing file, schema) before taking the lock
        lock = SessionLock(path)
        try:
            session = read_session(path)  # again: no other writer can append from here on
            if schema_major(session.schema_version) != schema_major(SCHEMA_VERSION):
                raise SchemaError(
                    f"{path}: schema version {session.schema_version} differs from this station's "
                    f"{SCHEMA_VERSION}; resume it with the station version that recorded it"
                )
            for stale in path.parent.glob(f".{path.name}.resume-*.tmp"):
                stale.unlink(missing_ok=True)  # left by a crash during an earlier resume
            with open_h5(path) as src:
                root = dict(src.attrs.items())
                meta = dict(src["meta"].attrs.items())
                resumes = session.resumed_utc + [resumed_utc or utc_now()]
                root.update(ended_utc="", outcome="", resumed_utc=json.dumps(resumes))
                tmp = _temp_path(path, "resume")
                try:
                    build_session_file(tmp, root, meta, session.points, session.faults, copy_from=src)
                except BaseException:
                    tmp.unlink(missing_ok=True)
                    raise
            _replace(tmp, path)
        except BaseException:
            lock.release()
            raise
        return cls(path, session.points["index"], len(session.faults), fsync, lock)

    # -- writing ---------------------------------------------------------------------------

    def append_point(self, record: PointRecord | Mapping[str, Any] | np.void) -> None:
        """Record one point (a PointRecord, or a dict of its field names; units in the names)

        When this returns, the row is in the journal and survives a kill of this process; it
        reaches /points with the next batch (see the module docstring).
        Raises InputError for an index already in the file (a resume must skip those).
        """
        index, raw = point_bytes(record)
        if index in self._indices:
            raise InputError(f"{self.path}: point index {index} is already recorded; a resume must skip it")
        if self._f is None or self._journal is None:
            raise InputError(f"{self.path}: the session file is closed")
        self._journal.append(raw)
        pending = self._pending
        pending.append(raw)
        self._indices.add(index)
        self._points_written += 1
        now = time.monotonic()
        if len(pending) == 1:
            self._pending_since = now
        elif len(pending) >= FLUSH_ROWS or now - self._pending_since >= FLUSH_S:
            self.flush()

    def flush(self) -> None:
        """Write the journalled points not yet in /points to the HDF5 file and flush it (a live
        HDF5 reader sees them from then on)."""
        if self._pending:
            rows = np.frombuffer(b"".join(self._pending), POINT_DTYPE)  # no field-by-field concatenate
            self._append(self._pds, self._ptype, rows)
            self._pending = []  # only once written: an interrupted write is tried again at close

    def append_points(self, records: np.ndarray) -> None:
        """Write many POINT_DTYPE rows with one flush (import, batch copy)."""
        rows = np.asarray(records)
        if rows.dtype != POINT_DTYPE:
            raise SchemaError(f"append_points needs a POINT_DTYPE array, got {rows.dtype}")
        rows = rows.reshape(-1)
        if not len(rows):
            return
        _check_point(rows)
        idx = rows["index"].tolist()
        dup = self._indices.intersection(idx)
        if dup or len(set(idx)) != len(idx):
            seen = dup or {i for i in idx if idx.count(i) > 1}
            raise InputError(f"{self.path}: point index {min(seen)} would be recorded twice")
        self.flush()
        self._append(self._pds, self._ptype, np.ascontiguousarray(rows))
        self._indices.update(idx)
        self._points_written += len(rows)

    def append_fault(self, record: Mapping[str, Any] | np.void) -> None:
        """Write one fault row (FAULT_DTYPE field names) and flush (the points before it too)."""
        self.flush()
        self._append(self._fds, self._ftype, fault_row(record))
        self._faults_written += 1

    def _append(self, ds: h5py.Dataset, mtype: h5py.h5t.TypeID, rows: np.ndarray) -> None:
        if self._f is None or not self._f.id.valid:
            raise InputError(f"{self.path}: the session file is closed")
        n0 = ds.shape[0]
        n = len(rows)
        try:
            ds.id.set_extent((n0 + n,))
            fspace = ds.id.get_space()
            fspace.select_hyperslab((n0,), (n,))
            ds.id.write(h5py.h5s.create_simple((n,)), fspace, rows, mtype=mtype)
            self._f.flush()
        except BaseException:
            # e.g. Ctrl-C (raised between two bytecodes, so possibly right after the extent
            # grew): leave no unwritten row behind; the point was not acknowledged
            ds.id.set_extent((n0,))
            raise
        if self._fsync:
            os.fsync(self._f.id.get_vfd_handle())

    # -- ending ----------------------------------------------------------------------------

    def finish(self, outcome: Outcome | str) -> None:
        """Record `outcome` (COMPLETED, ABORTED or FAILED, or their strings) and the end time,
        and close. The attribute holds the plain string ("completed", ...).

        The end attributes are written after leaving SWMR mode (close, reopen): a kill in
        between leaves every point and an unset outcome, read back as "incomplete".
        """
        written = Outcome.written()
        if outcome not in written:
            # refuse before closing anything: the caller can still finish with a valid outcome
            raise ValueError(f"outcome must be one of {', '.join(written)}, got {outcome!r}")
        outcome = Outcome(outcome)
        self._close_file()
        try:
            try:
                f = h5py.File(self.path, "a", libver=LIBVER)
            except BlockingIOError:
                # a live reader (SWMR, e.g. the UI's plot) holds a shared lock: the two attributes
                # are written anyway; the reader only follows /points, which does not change
                f = h5py.File(self.path, "a", libver=LIBVER, locking=False)
            with f:
                f.attrs["ended_utc"] = utc_now()
                f.attrs["outcome"] = outcome.value  # a plain str: h5py stores it as before
            _fsync_path(self.path)
        finally:
            self._lock.release()
        self._finished_outcome = outcome

    def close(self) -> None:
        """Flush and close the file (idempotent). The outcome stays unset unless `finish` ran."""
        try:
            self._close_file()
        finally:
            self._lock.release()

    def _close_file(self) -> None:
        try:
            if self._f is not None and self._f.id.valid:
                self.flush()
                self._f.flush()
                self._f.close()
                if self._journal is not None:
                    self._journal.remove()  # every row is in the closed file now
        finally:
            if self._f is not None and self._f.id.valid:
                self._f.close()  # the batch could not be written: its rows stay in the journal
            if self._journal is not None:
                self._journal.close()
            self._journal = None
            self._f = None

    @property
    def closed(self) -> bool:
        return self._f is None

    def __enter__(self) -> "SessionWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None or self._finished_outcome is not None or self.closed:
            self.close()
            return
        try:
            self.finish(Outcome.ABORTED if issubclass(exc_type, KeyboardInterrupt) else Outcome.FAILED)
        except Exception:
            self.close()

    # -- state -----------------------------------------------------------------------------

    @property
    def points_written(self) -> int:
        """Rows in /points, including those recorded before a resume."""
        return self._points_written

    @property
    def faults_written(self) -> int:
        return self._faults_written

    def indices_written(self) -> set[int]:
        """Plan indices of the points in the file (a copy)."""
        return set(self._indices)

