"""All-or-nothing writes for procedures and the front ends: files and folders appear complete or
not at all (drivers.atomic does the writing: temporary name beside the target, fsync, rename,
the process umask honoured).

A failure (read-only folder, disk full, missing folder) raises `WriteError`, an InputError that
names the path and what to do (front ends print the line and exit 2), and leaves nothing behind.
Session files are not written here: a sweep writes its session in place by design
(procedures.io.recording), so that a crash keeps every point recorded so far.
"""

from __future__ import annotations

import errno
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

import drivers.atomic as _raw
from drivers.atomic import file_mode, umask  # noqa: F401  (re-exported)
from procedures.vocabulary import InputError

# OSErrors that say "this place cannot take the file" rather than "the program is wrong"
_PLACE_ERRNOS = {errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOSPC, errno.EDQUOT, errno.EFBIG}


class WriteError(InputError):
    """An output could not be written (read-only folder, disk full, missing folder). Nothing was left."""


def write_error(path: str | os.PathLike, err: OSError) -> WriteError:
    """The WriteError for `err` met while writing `path`: the path, the reason, what to do."""
    if err.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        todo = "free some space or choose another folder"
    elif err.errno in (errno.ENOENT, errno.ENOTDIR):
        todo = "the folder does not exist; create it or choose another"
    elif err.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        todo = "choose a writable folder"
    else:
        todo = "choose another place to write"
    return WriteError(f"{path}: cannot write ({err.strerror or err}); {todo}")


@contextmanager
def atomic_paths(paths: Iterable[str | os.PathLike], suffix: str = "", exists: bool = True) -> Iterator[dict[Path, Path]]:
    """drivers.atomic.atomic_paths (temporary paths for files written by libraries, renamed into
    place together when the block ends without an exception), failures as WriteError."""
    paths = [Path(p) for p in paths]
    try:
        with _raw.atomic_paths(paths, suffix, exists) as temps:
            try:
                yield temps
            except OSError as err:  # the library's write to a temporary: disk full, quota
                if err.errno in _PLACE_ERRNOS and (err.filename is None or Path(os.fsdecode(err.filename))
                                                   in temps.values()):
                    raise _raw.TargetError(paths[0], err) from err
                raise
    except _raw.TargetError as err:
        raise write_error(err.target, err) from None


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = "", exists: bool = True) -> Iterator[Path]:
    """One file of `atomic_paths`: yields the temporary path to write."""
    with atomic_paths([path], suffix, exists) as temps:
        yield next(iter(temps.values()))


def write_files_atomic(files: Mapping[str | os.PathLike, bytes | str], encoding: str = "utf-8") -> list[Path]:
    """Write every file or none (str encoded, no newline translation); failures as WriteError."""
    try:
        return _raw.write_files_atomic(files, encoding)
    except _raw.TargetError as err:
        raise write_error(err.target, err) from None


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write `data` to `path` all or nothing."""
    return write_files_atomic({path: data})[0]


def write_text_atomic(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Write `text` to `path` all or nothing (no newline translation)."""
    return write_files_atomic({path: text}, encoding)[0]


def _merge_into(src: Path, dst: Path) -> None:
    """Move src's entries into the existing folder dst, one rename each (files replace files)."""
    for entry in sorted(src.iterdir()):
        target = dst / entry.name
        if entry.is_dir() and target.is_dir():
            _merge_into(entry, target)
        else:
            os.replace(entry, target)


@contextmanager
def atomic_folder(path: str | os.PathLike) -> Iterator[Path]:
    """Build a folder under a temporary sibling name (yielded) and put it into place only when the
    block ends without an exception; an exception (Ctrl-C included) removes it: no half folder.

    A folder that does not exist yet appears at once, by one rename. Into a folder that already
    exists (it may hold the user's other files) the new entries are moved, one rename each, only
    after all were written."""
    target = Path(os.path.abspath(path))
    try:
        if target.exists() and not target.is_dir():
            raise WriteError(f"{path}: exists and is not a folder; choose a folder name for the output")
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".partial", dir=target.parent))
    except OSError as err:
        raise write_error(path, err) from None
    try:
        try:
            yield tmp
        except OSError as err:
            if err.errno in _PLACE_ERRNOS:
                raise write_error(path, err) from None
            raise
        try:
            os.chmod(tmp, 0o777 & ~umask())  # mkdtemp gives 0700
            if target.is_dir():
                _merge_into(tmp, target)
            else:
                os.replace(tmp, target)
        except OSError as err:
            raise write_error(path, err) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
