"""Checked reading of HDF5 session files: whole sessions, and rows of a file still growing.

A file cut short by a kill is opened in SWMR read mode (its "open for writing" flag is still
set); rows allocated but never written (index = -1, see schema.UNWRITTEN_INDEX) are dropped.
Schema versions with another major number are refused with a message saying what to do.

Damaged files (a copy cut short by a full disk or a pulled USB stick, zeroed or overwritten
blocks) are refused with an InputError naming the file and what to do, within seconds. Every
open of a session file goes through `open_h5`, which guards it in two steps:

1. a structural check without HDF5 (`check_file`): a file shorter than the end-of-file address
   its superblock records was cut short. HDF5 makes that check itself only outside SWMR mode;
   in SWMR read mode (needed for killed files) it walks the missing bytes, retrying each failed
   metadata read with sleeps, for many minutes.
2. a time bound (`probe`): HDF5 can also loop for ever inside one call on a file of the right
   size with damaged content (zeroed global heap objects, for one), in normal mode too. So a
   child process reads the file whole first, as a reader would, and is killed when that takes
   longer than PROBE_TIMEOUT_S.

HDF5 errors while reading are refused as damaged; the points read are checked against bounds
no rig can exceed (`check_points`), so garbage in raw data does not reach an analysis.
"""

from __future__ import annotations

import atexit
import hashlib
import json
import os
import select
import struct
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from procedures.vocabulary import InputError, SchemaError
from procedures.io.ranges import SESSION_BOUNDS
from procedures.io.recording.identity import SessionIdentity, identity_of_meta
from procedures.io.recording.journal import merge_journal, read_journal_raw
from procedures.io.recording.schema import (
    ADDED_POINT_FIELDS,
    FAULT_DTYPE,
    META_ATTRS,
    OPTIONAL_NAN_FIELDS,
    POINT_DTYPE,
    ROOT_ATTRS,
    SCHEMA_VERSION,
    UNWRITTEN_INDEX,
    schema_major,
)

_REQUIRED_ROOT = tuple(a for a in ROOT_ATTRS if a != "resumed_utc")  # resumed_utc: optional, "[]"


@dataclass(frozen=True)
class Session:
    """One session file as read.

    `points` (POINT_DTYPE) and `faults` (FAULT_DTYPE) are in file order; `attrs` holds the root
    attributes (str); `outcome` is the root outcome, or "incomplete" when none was recorded
    (the session was cut short or is still being written). `unwritten_rows` counts rows
    allocated but never written (a kill mid-append), which are not in `points`.
    """

    path: Path
    sha256: str
    points: np.ndarray
    faults: np.ndarray
    attrs: dict[str, Any]
    plan: dict
    station_config: dict
    devices: dict
    schema_version: str
    outcome: str
    unwritten_rows: int = 0
    resumed_utc: list[str] = field(default_factory=list)
    identity: SessionIdentity = field(default_factory=SessionIdentity.unknown)
    """Leg, drive, station, instrument, operator (schema 1.1, /meta/identity); unknown in 1.0 files."""

    @property
    def stage(self) -> str:
        """The stage of the leg's life this session records: "as_found", "as_left" or "other"
        (root attribute `stage`, derived for files before schema 1.2; procedures/io/recording/stage.py)."""
        from procedures.io.recording.stage import stage_of_session

        return stage_of_session(self)

    @property
    def legs(self) -> list[int]:
        """Leg numbers present in `points`, ascending."""
        return sorted({int(v) for v in self.points["leg"]})

    @property
    def indices(self) -> set[int]:
        return {int(v) for v in self.points["index"]}


def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of the file's bytes (names the recording an analysis came from)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# -- guards against damaged files ------------------------------------------------------------

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
PROBE_TIMEOUT_S = 2.0
"""Time bound of the child process's read of a file (see `probe`). A healthy 26 000-point
session is read in a few hundredths of a second."""

_LIVE_SETTLE_S = 0.5  # a writer's flush may extend the file just after writing the superblock
_COPY_AGAIN = "copy it again from the original session file"


@dataclass(frozen=True)
class Superblock:
    """What an HDF5 superblock says about its file (read without HDF5)."""

    offset: int  # where the superblock starts (0, or after a user block: 512, 1024, ...)
    version: int
    eof: int | None  # the end-of-file address: the size of the complete file (None: unknown)
    open_for_write: bool  # a writer had it open and did not close it (killed, or still writing)


def read_superblock(path: str | os.PathLike) -> Superblock | None:
    """The superblock of an HDF5 file, or None when the file has no HDF5 signature.

    The signature is at 0 or at 512, 1024, 2048, ... (after a user block). Versions 0-3 are
    understood (HDF5 file format specification, section II.A); for anything else `eof` is None.
    """
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        offset = 0
        while offset + len(HDF5_SIGNATURE) <= size:
            fh.seek(offset)
            head = fh.read(96)
            if head.startswith(HDF5_SIGNATURE):
                return _parse_superblock(offset, head)
            offset = 512 if offset == 0 else offset * 2
    return None


def _parse_superblock(offset: int, head: bytes) -> Superblock:
    version = head[8] if len(head) > 8 else -1
    if version in (0, 1):
        sizes_at, flags_at, addr_at = 13, 20, 24 if version == 0 else 28
        base_index, eof_index = 0, 2  # base, free-space info, end of file, driver info
        flags_len = 4
    elif version in (2, 3):
        sizes_at, flags_at, addr_at = 9, 11, 12
        base_index, eof_index = 0, 2  # base, superblock extension, end of file, root header
        flags_len = 1
    else:
        return Superblock(offset, version, None, False)
    width = head[sizes_at] if len(head) > sizes_at else 0
    fmt = {2: "<H", 4: "<I", 8: "<Q"}.get(width)
    end = addr_at + (eof_index + 1) * width
    if fmt is None or len(head) < end:
        return Superblock(offset, version, None, False)
    flags = int.from_bytes(head[flags_at:flags_at + flags_len], "little")
    eof = struct.unpack_from(fmt, head, addr_at + eof_index * width)[0]
    undefined = (1 << (8 * width)) - 1
    # v3 marks a file opened for writing (bit 0) and for SWMR writing (bit 2) until it is closed
    return Superblock(offset, version, None if eof == undefined else eof, version >= 3 and bool(flags & 0b101))


def check_file(path: str | os.PathLike) -> Superblock:
    """Check a session file's structure before HDF5 reads it; return its superblock.

    InputError (one line naming the file and what to do) for a missing path, a directory, an
    empty file, a file without an HDF5 signature, and a file shorter than the end-of-file
    address its superblock records (cut short). Fast: reads at most a few hundred bytes.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not a session file")
    size = path.stat().st_size
    if size == 0:
        raise InputError(f"{path}: the file is empty (0 bytes); {_COPY_AGAIN}")
    sb = read_superblock(path)
    if sb is None:
        with open(path, "rb") as fh:
            start = fh.read(200)
        from procedures.io.integrity import file_kind, wrong_kind  # here: read only for a file that is no HDF5

        other = wrong_kind(path, "session", "give the session file (HDF5) a sweep or `station import` wrote")
        if other and file_kind(path) != "points":  # a table, model, serials list, ... given as a session: named
            raise InputError(other)
        if b"," in start and b"\0" not in start:
            raise InputError(f"{path}: not an HDF5 file (is it a CSV? use `station import`)")
        raise InputError(f"{path}: not an HDF5 session file (no HDF5 signature); {_COPY_AGAIN}")
    if sb.eof is None:
        return sb  # a superblock this check does not understand: HDF5 decides
    deadline = time.monotonic() + (_LIVE_SETTLE_S if sb.open_for_write else 0.0)
    while size < sb.eof and time.monotonic() < deadline:
        time.sleep(0.05)  # a writer between writing the superblock and extending the file
        sb = read_superblock(path) or sb
        size = path.stat().st_size
    if sb.eof is not None and size < sb.eof:
        raise InputError(
            f"{path}: the file is cut short ({size} of {sb.eof} bytes, {100 * size / sb.eof:.0f} %; "
            f"an interrupted copy, a full disk or a pulled USB stick?); {_COPY_AGAIN}"
        )
    return sb


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def damaged(path: str | os.PathLike, detail: str) -> InputError:
    """The error for a file HDF5 cannot read (or reads as garbage)."""
    return InputError(f"{path}: the file is damaged ({detail}); {_COPY_AGAIN}")


# The time bound. HDF5 can loop for ever inside one call on a damaged file (e.g. a global heap
# whose object headers were zeroed), and a thread stuck in HDF5 holds h5py's global lock, so
# nothing else in the process could read HDF5 either. So every file is first read whole, as a
# reader would, by a child process that is killed when it takes longer than PROBE_TIMEOUT_S.
# The child stays alive between files (starting Python and h5py costs a few tenths of a second).
_PROBE_WORKER = r"""
import json, signal, sys, h5py
def touch(obj):
    for key in obj.attrs:
        obj.attrs[key]
def visit(name, obj):
    touch(obj)
    if isinstance(obj, h5py.Dataset):
        obj[...]
print("ready", flush=True)
for line in sys.stdin:
    path, swmr, alarm_s = json.loads(line)
    signal.alarm(alarm_s)  # ends this process if it is stuck in HDF5 and its parent died meanwhile
    try:
        try:
            f = h5py.File(path, "r")
        except OSError:
            if not swmr:
                raise
            f = h5py.File(path, "r", swmr=True)
        with f:
            touch(f)
            f.visititems(visit)
        print("ok", flush=True)
    except Exception as exc:
        print("error " + " ".join(str(exc).split())[:300], flush=True)
    signal.alarm(0)
"""
_PROBE_START_TIMEOUT_S = 60.0  # starting Python and h5py on a loaded machine: not the file's fault


class _Prober:
    """The child process that reads files with a time bound (one per process, started on first use)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._proc: subprocess.Popen | None = None
        self._pid = 0
        self._buf = b""
        self._done: dict[tuple, None] = {}  # files read fine, by identity, size and mtime
        atexit.register(self.stop)

    def stop(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None and self._pid == os.getpid():
            proc.kill()
            proc.wait()
            for stream in (proc.stdin, proc.stdout):
                try:
                    stream.close()
                except OSError:
                    pass

    def _start(self) -> subprocess.Popen:
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
        self._proc = subprocess.Popen([sys.executable, "-c", _PROBE_WORKER], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env)
        self._pid, self._buf = os.getpid(), b""
        if self._readline(_PROBE_START_TIMEOUT_S) != "ready":
            self.stop()
            raise RuntimeError(f"the HDF5 check process ({sys.executable}) did not start")
        return self._proc

    def _readline(self, timeout_s: float) -> str | None:
        """One line from the child, or None when none came within `timeout_s` (or it died)."""
        fd = self._proc.stdout.fileno()
        deadline = time.monotonic() + timeout_s
        while b"\n" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                return None
            chunk = os.read(fd, 65536)
            if not chunk:
                return None
            self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        return line.decode("utf-8", "replace")

    def probe(self, path: Path, swmr: bool, timeout_s: float) -> str | None:
        """None when the child read `path` within `timeout_s`; else why not."""
        st = path.stat()
        key = (str(path.resolve()), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, swmr)
        with self._lock:
            if key in self._done:
                return None
            if self._proc is None or self._pid != os.getpid() or self._proc.poll() is not None:
                self._proc = None  # not ours (forked) or dead: start another
                self._start()
            request = (json.dumps([str(path.resolve()), swmr, int(timeout_s) + 10]) + "\n").encode()
            try:
                self._proc.stdin.write(request)
                self._proc.stdin.flush()
            except OSError:
                self.stop()
                self._start()
                self._proc.stdin.write(request)
                self._proc.stdin.flush()
            answer = self._readline(timeout_s)
            if answer is None:
                self.stop()  # stuck inside HDF5: only killing it ends that
                return f"HDF5 did not finish reading it within {timeout_s:g} s"
            if answer == "ok":
                if len(self._done) > 256:
                    self._done.clear()
                self._done[key] = None
                return None
            return "HDF5: " + answer.removeprefix("error ")


_prober = _Prober()


def probe(path: str | os.PathLike, swmr: bool = False, timeout_s: float | None = None) -> None:
    """Read the whole file as a reader would (every attribute and dataset) in a child process;
    InputError when HDF5 fails on it or does not finish within `timeout_s` (default
    PROBE_TIMEOUT_S): the file is damaged. `swmr`: also try SWMR read mode, as `open_h5` does
    for a file a writer left open. A file already read fine (same inode, size, mtime) is not
    read again."""
    path = Path(path)
    why = _prober.probe(path, swmr, PROBE_TIMEOUT_S if timeout_s is None else timeout_s)
    if why:
        raise damaged(path, why)


def open_h5(path: str | os.PathLike) -> h5py.File:
    """Open a session file read-only, also when it is being written or was killed (SWMR read).

    Guarded (see the module docstring): raises InputError, within seconds, when the path is
    missing, not an HDF5 file, cut short or damaged.
    """
    path = Path(path)
    sb = check_file(path)
    probe(path, swmr=sb.open_for_write)
    try:
        return h5py.File(path, "r")
    except OSError as first:
        if not sb.open_for_write:
            raise damaged(path, f"HDF5: {_one_line(first)}") from None
    try:
        # open for writing elsewhere, or killed while open: SWMR read ignores that flag
        return h5py.File(path, "r", swmr=True)
    except OSError as exc:
        raise damaged(path, f"HDF5: {_one_line(exc)}") from None


def _text(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def check_schema(f: h5py.File, path: Path) -> str:
    """Return the file's schema version; SchemaError if absent or of another major version."""
    if "schema_version" not in f.attrs:
        raise SchemaError(f"{path}: not a station session file (no schema_version attribute on the root group)")
    version = str(_text(f.attrs["schema_version"]))
    ours = schema_major(SCHEMA_VERSION)
    try:
        major = schema_major(version)
    except ValueError:
        raise SchemaError(f"{path}: schema version {version!r} is not of the form major.minor") from None
    if major > ours:
        raise SchemaError(
            f"{path}: schema version {version} is newer than this station understands ({ours}.x); update station"
        )
    if major < ours:
        raise SchemaError(
            f"{path}: schema version {version} is older than this station understands ({ours}.x); "
            "convert it with the station version that wrote it"
        )
    return version


def _rows(f: h5py.File, name: str, dtype: np.dtype, path: Path) -> np.ndarray:
    """Dataset `name` converted to `dtype` (extra fields of a newer minor version dropped)."""
    if name not in f or not isinstance(f[name], h5py.Dataset):
        raise SchemaError(f"{path}: dataset /{name} is missing")
    ds = f[name]
    have = ds.dtype.names or ()
    missing = [n for n in dtype.names if n not in have and n not in ADDED_POINT_FIELDS]
    if missing:
        raise SchemaError(f"{path}: /{name} lacks field(s) {', '.join(missing)}")
    if ds.ndim != 1:
        raise SchemaError(f"{path}: /{name} must be one-dimensional, has shape {ds.shape}")
    data = ds[...]
    if data.dtype == dtype:
        return data
    out = np.empty(len(data), dtype)
    for n in dtype.names:
        out[n] = data[n] if n in have else np.nan  # a field added later: unknown in older files
    return out


def _meta_json(f: h5py.File, key: str, path: Path) -> dict:
    if "meta" not in f:
        raise SchemaError(f"{path}: group /meta is missing")
    if key not in f["meta"].attrs:
        raise SchemaError(f"{path}: attribute /meta/{key} is missing")
    text = _text(f["meta"].attrs[key])
    try:
        value = json.loads(text)
    except (TypeError, ValueError) as exc:
        raise SchemaError(f"{path}: attribute /meta/{key} is not valid JSON ({exc})") from None
    if not isinstance(value, dict):  # every reader of plan/station_config/devices takes an object
        raise SchemaError(f"{path}: attribute /meta/{key} is JSON {type(value).__name__}, not an object; "
                          f"{_COPY_AGAIN}")
    return value


_CHECKED_FIELDS = ("leg", "run", "direction", "target_mm", "error_um") + tuple(OPTIONAL_NAN_FIELDS)


def check_points(points: np.ndarray, path: str | os.PathLike, plan: Any = None) -> None:
    """Refuse (InputError naming file, row and field) points no rig can have recorded: a leg
    outside 1-6 or not among the legs the plan declares, a run below 1, a direction other than
    +/-1, a duplicate or negative index, a target that is NaN or a metre from mid-stroke, an
    infinite value or one beyond `ranges.SESSION_BOUNDS`. Such values come from a damaged file."""
    bounds = SESSION_BOUNDS
    declared = plan.get("legs") if isinstance(plan, dict) else None
    if isinstance(declared, list) and declared and all(isinstance(v, int) and 1 <= v <= 6 for v in declared):
        bounds = replace(bounds, legs=tuple(sorted(declared)))
    found = bounds.check_array(points, _CHECKED_FIELDS, required=("target_mm",))
    index = points["index"]
    if found is None and len(index):
        negative = np.flatnonzero(index < 0)
        order = np.argsort(index, kind="stable")
        twice = np.flatnonzero(np.diff(index[order]) == 0)
        if negative.size:
            i = int(negative[0])
            found = (i, "index", f"index {int(index[i])} is negative", int(negative.size))
        elif twice.size:
            i = int(order[twice[0] + 1])
            found = (i, "index", f"index {int(index[i])} appears twice (a point's plan index is unique)",
                     int(twice.size))
    if found is None:
        return
    row, name, reason, count = found
    more = f" (and {count - 1} more row{'s' if count > 2 else ''})" if count > 1 else ""
    if name == "leg":
        reason += " the session's plan declares" if bounds.legs != SESSION_BOUNDS.legs else " of a hexapod"
    raise InputError(f"{path}: /points row {row}, field {name}: {reason}{more}; the file is damaged or was "
                     f"not written by station: {_COPY_AGAIN}")


def read_session(path: str | os.PathLike) -> Session:
    """Read and check a session file (also one cut short by a kill, or still being written).

    Raises InputError (missing / not HDF5) or SchemaError (another major schema version, a
    missing dataset, field or attribute) with a message naming the file and what is wrong.
    """
    path = Path(path)
    # the journal before the HDF5 file: a batch the writer moves from one to the other meanwhile
    # is then seen at least once (rows are told apart by index)
    journal = read_journal_raw(path)
    with open_h5(path) as f:
        try:
            version = check_schema(f, path)
            for key in _REQUIRED_ROOT:
                if key not in f.attrs:
                    raise SchemaError(f"{path}: root attribute {key} is missing")
            attrs = {k: _text(v) for k, v in f.attrs.items()}
            points = _rows(f, "points", POINT_DTYPE, path)
            faults = _rows(f, "faults", FAULT_DTYPE, path)
            meta = {key: _meta_json(f, key, path) for key in META_ATTRS}
            identity = identity_of_meta(f["meta"].attrs, str(path))
        except InputError:
            raise
        except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:  # what h5py raises for HDF5 errors
            raise damaged(path, f"HDF5: {_one_line(exc)}") from None
    sha = file_sha256(path)
    written = points["index"] != UNWRITTEN_INDEX
    unwritten = int(np.count_nonzero(~written))
    if unwritten:
        points = points[written]
    faults = faults[faults["index"] != UNWRITTEN_INDEX]
    if not attrs.get("outcome"):  # cut short or still written: its last points may be journalled only
        points = merge_journal(points, journal.rows(str(attrs.get("session_id", ""))))
    check_points(points, path, meta["plan"])
    try:
        resumed = json.loads(attrs.get("resumed_utc", "[]") or "[]")
    except (TypeError, ValueError):  # not text (an array), or not JSON
        resumed = None
    if not isinstance(resumed, list) or not all(isinstance(t, str) for t in resumed):
        raise SchemaError(f"{path}: root attribute resumed_utc is not a JSON list of UTC times") from None
    return Session(
        path=path,
        sha256=sha,
        points=points,
        faults=faults,
        attrs=attrs,
        plan=meta["plan"],
        station_config=meta["station_config"],
        devices=meta["devices"],
        schema_version=version,
        outcome=str(attrs.get("outcome") or "incomplete"),
        unwritten_rows=unwritten,
        resumed_utc=list(resumed),
        identity=identity,
    )


class LiveReader:
    """Follows a session file while another process writes it (SWMR read, and the writer's
    journal: every acknowledged point, not only those of its last batch).

    `poll()` returns the rows added since the previous call (POINT_DTYPE). It never returns a
    row that is allocated but not yet written; such a row comes with a later poll.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._f = open_h5(self.path)
        try:
            self.schema_version = check_schema(self._f, self.path)
            if "points" not in self._f:
                raise SchemaError(f"{self.path}: dataset /points is missing")
            self._ds = self._f["points"]
            self._session_id = str(_text(self._f.attrs.get("session_id", "")))
        except BaseException as exc:
            self._f.close()
            if isinstance(exc, (OSError, RuntimeError, KeyError)):
                raise damaged(self.path, f"HDF5: {_one_line(exc)}") from None
            raise
        self._next = 0  # rows of /points read
        self._journal_at = 0  # bytes of the writer's journal read
        self._seen: set[int] = set()  # indices returned (from either)

    def poll(self) -> np.ndarray:
        """New rows since the last call (possibly none): those in /points, then those the writer
        has acknowledged but not yet written there (its journal, read first: a batch moved from
        one to the other meanwhile is seen at least once; rows are told apart by index)."""
        journal = read_journal_raw(self.path, self._journal_at)
        self._journal_at = journal.end
        try:
            if self._f.swmr_mode:
                self._ds.refresh()
            n = self._ds.shape[0]
            data = self._ds[self._next : n] if n > self._next else np.empty(0, self._ds.dtype)
        except (OSError, RuntimeError) as exc:
            raise damaged(self.path, f"HDF5: {_one_line(exc)}") from None
        gaps = np.flatnonzero(data["index"] == UNWRITTEN_INDEX)
        if gaps.size:
            data = data[: gaps[0]]
        self._next += len(data)
        if data.dtype != POINT_DTYPE:
            out = np.empty(len(data), POINT_DTYPE)
            for name in POINT_DTYPE.names:
                out[name] = data[name]
            data = out
        data = np.concatenate([data, journal.rows(self._session_id)]) if journal.data else data
        if not len(data):
            return data
        keep = np.fromiter((int(i) not in self._seen for i in data["index"]), bool, len(data))
        data = data[keep]
        _, first = np.unique(data["index"], return_index=True)
        data = data[np.sort(first)]
        self._seen.update(int(i) for i in data["index"])
        return data

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> "LiveReader":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_identity(source: str | os.PathLike | Any) -> SessionIdentity:
    """The identity of a session: `source` is a path or an open h5py File. A file without one
    (schema 1.0, an import) gives `SessionIdentity.unknown()`."""
    if isinstance(source, (str, os.PathLike)):
        with open_h5(Path(source)) as f:  # the guarded open (damaged files refused)
            return read_identity(f)
    meta = source["meta"] if "meta" in source else None
    return identity_of_meta(meta.attrs if meta is not None else {}, str(getattr(source, "filename", "session")))
