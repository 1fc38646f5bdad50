"""The point journal: an append-only sidecar that makes a point durable with one os.write.

A writer (writer.SessionWriter) appends each point's POINT_DTYPE row, as raw bytes, to
`.NAME.journal` beside the session before it acknowledges the point, and writes /points of the
HDF5 file in batches. A write(2) that returned is in the kernel's page cache: it survives a kill
of the process (SIGKILL, crash, Ctrl-C), as the flushed HDF5 append per point did, for about a
tenth of the CPU. Readers of a session cut short (reader.read_session, reader.LiveReader, and so
`SessionWriter.resume`) add the journal's rows whose index is not in /points yet. A clean close
writes every row to the HDF5 file and removes the journal.

Layout: MAGIC, then a little-endian uint32 row size and uint32 length of a JSON header
({"session_id": ..., "dtype": POINT_DTYPE.descr as text}), the header, then rows of that size,
back to back. A row cut short by a kill mid-write is ignored (it was not acknowledged).
"""

from __future__ import annotations

import json
import os
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from procedures.io.recording.schema import POINT_DTYPE

MAGIC = b"STNJRNL1"
_HEAD = struct.Struct("<II")
_DESCR = str(POINT_DTYPE.descr)


def journal_path(path: str | os.PathLike) -> Path:
    """`.NAME.journal` beside the session file `path` (hidden, like the writer's lock file)."""
    path = Path(path)
    return path.with_name(f".{path.name}.journal")


def _header(session_id: str) -> bytes:
    text = json.dumps({"session_id": session_id, "dtype": _DESCR}).encode()
    return MAGIC + _HEAD.pack(POINT_DTYPE.itemsize, len(text)) + text


class Journal:
    """The writing end: `append(row_bytes)` is one os.write (O_APPEND); `remove()` at a clean close."""

    def __init__(self, session_path: Path, session_id: str, fsync: bool = False) -> None:
        self.path = journal_path(session_path)
        self._fsync = fsync
        # truncated: rows of an earlier writer of this file are in /points by now (a resume
        # rebuilt the file from them before this opens)
        self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o644)
        os.write(self._fd, _header(session_id))
        if fsync:
            os.fsync(self._fd)

    def append(self, row: bytes) -> None:
        if os.write(self._fd, row) != len(row):  # a regular file: short only when the disk is full
            raise OSError(f"{self.path}: short write (disk full?)")
        if self._fsync:
            os.fsync(self._fd)

    def close(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            os.close(fd)

    def remove(self) -> None:
        """Close and delete: call only once every row is in the HDF5 file and flushed."""
        self.close()
        self.path.unlink(missing_ok=True)


@dataclass(frozen=True)
class JournalRead:
    """What `read_journal_raw` found: the header's session id (None: no journal, or not one of
    this station's row layout), the complete rows' bytes, and the offset after them."""

    session_id: str | None
    data: bytes
    end: int

    def rows(self, session_id: str) -> np.ndarray:
        """The rows (POINT_DTYPE), if the journal is the session `session_id`'s (else none)."""
        if self.session_id is None or self.session_id != session_id:
            return np.empty(0, POINT_DTYPE)
        return np.frombuffer(self.data, POINT_DTYPE).copy()


def read_journal_raw(session_path: str | os.PathLike, offset: int = 0) -> JournalRead:
    """The complete rows of the session's journal from byte `offset` (0: from the first row).
    A row cut short at the end (a kill mid-write: never acknowledged) is left out."""
    none = JournalRead(None, b"", offset)
    try:
        with open(journal_path(session_path), "rb") as fh:
            head = fh.read(len(MAGIC) + _HEAD.size)
            if len(head) < len(MAGIC) + _HEAD.size or not head.startswith(MAGIC):
                return none
            size, n = _HEAD.unpack_from(head, len(MAGIC))
            try:
                info = json.loads(fh.read(n))
            except ValueError:
                return none
            if size != POINT_DTYPE.itemsize or not isinstance(info, dict) or info.get("dtype") != _DESCR:
                return none
            start = max(offset, len(head) + n)
            fh.seek(start)
            data = fh.read()
    except FileNotFoundError:
        return none
    whole = len(data) - len(data) % size
    return JournalRead(str(info.get("session_id")), data[:whole], start + whole)


def merge_journal(points: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """`points` followed by the journal `rows` whose index is not among them (file order kept)."""
    if not len(rows):
        return points
    new = rows[~np.isin(rows["index"], points["index"])]
    if not len(new):
        return points
    _, first = np.unique(new["index"], return_index=True)  # a row is written once; be safe
    return np.concatenate([points, new[np.sort(first)]])
