"""Checked reading of HDF5 session files: whole sessions, and rows of a file still growing.

A file cut short by a kill is opened in SWMR read mode (its "open for writing" flag is still
set); rows allocated but never written (index = -1, see schema.UNWRITTEN_INDEX) are dropped.
Schema versions with another major number are refused with a message saying what to do.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from procedures.errors import InputError, SchemaError
from procedures.recording.schema import (
    FAULT_DTYPE,
    META_ATTRS,
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


def open_h5(path: str | os.PathLike) -> h5py.File:
    """Open a session file read-only, also when it is being written or was killed (SWMR read).

    Raises InputError when the path is missing or not an HDF5 file.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not a session file")
    try:
        return h5py.File(path, "r")
    except OSError as first:
        try:
            # open for writing elsewhere, or killed while open: SWMR read ignores that flag
            return h5py.File(path, "r", swmr=True)
        except OSError:
            if not h5py.is_hdf5(path):
                raise InputError(f"{path}: not an HDF5 file (is it a CSV? use `station import`)") from first
            raise InputError(f"{path}: cannot be opened as HDF5 ({first})") from first


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
    missing = [n for n in dtype.names if n not in have]
    if missing:
        raise SchemaError(f"{path}: /{name} lacks field(s) {', '.join(missing)}")
    if ds.ndim != 1:
        raise SchemaError(f"{path}: /{name} must be one-dimensional, has shape {ds.shape}")
    data = ds[...]
    if data.dtype == dtype:
        return data
    out = np.empty(len(data), dtype)
    for n in dtype.names:
        out[n] = data[n]
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
    return value


def read_session(path: str | os.PathLike) -> Session:
    """Read and check a session file (also one cut short by a kill, or still being written).

    Raises InputError (missing / not HDF5) or SchemaError (another major schema version, a
    missing dataset, field or attribute) with a message naming the file and what is wrong.
    """
    path = Path(path)
    sha = file_sha256(path) if path.is_file() else ""
    with open_h5(path) as f:
        version = check_schema(f, path)
        for key in _REQUIRED_ROOT:
            if key not in f.attrs:
                raise SchemaError(f"{path}: root attribute {key} is missing")
        attrs = {k: _text(v) for k, v in f.attrs.items()}
        points = _rows(f, "points", POINT_DTYPE, path)
        faults = _rows(f, "faults", FAULT_DTYPE, path)
        meta = {key: _meta_json(f, key, path) for key in META_ATTRS}
    written = points["index"] != UNWRITTEN_INDEX
    unwritten = int(np.count_nonzero(~written))
    if unwritten:
        points = points[written]
    faults = faults[faults["index"] != UNWRITTEN_INDEX]
    try:
        resumed = json.loads(attrs.get("resumed_utc", "[]") or "[]")
    except ValueError:
        raise SchemaError(f"{path}: root attribute resumed_utc is not a JSON list") from None
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
    )


class LiveReader:
    """Follows a session file while another process writes it (SWMR read).

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
        except BaseException:
            self._f.close()
            raise
        self._next = 0

    def poll(self) -> np.ndarray:
        """New rows since the last call (possibly none)."""
        if self._f.swmr_mode:
            self._ds.refresh()
        n = self._ds.shape[0]
        if n <= self._next:
            return np.empty(0, POINT_DTYPE)
        data = self._ds[self._next : n]
        gaps = np.flatnonzero(data["index"] == UNWRITTEN_INDEX)
        if gaps.size:
            data = data[: gaps[0]]
        self._next += len(data)
        if data.dtype != POINT_DTYPE:
            out = np.empty(len(data), POINT_DTYPE)
            for name in POINT_DTYPE.names:
                out[name] = data[name]
            data = out
        return data

    @property
    def rows_read(self) -> int:
        return self._next

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> "LiveReader":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
