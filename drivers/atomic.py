"""The all-or-nothing file write every layer uses (procedures.io.atomic_outputs wraps it for the front ends).

A file is written to a temporary name beside its target, fsynced, and renamed into place (the folder fsynced too), so a
crash, a full disk or Ctrl-C never leaves half a file; new files honour the process umask
(0o666 & ~umask, as `open()` gives; `mkstemp` alone gives 0600). Failures are plain OSError
here (drivers know no InputError); nothing temporary is left behind.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path


def umask() -> int:
    """The process umask, read without changing it where the system allows (Linux /proc)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    old = os.umask(0o022)  # fallback: set and restore (not thread-safe, hence the /proc read first)
    os.umask(old)
    return old


def file_mode() -> int:
    """The mode `open()` gives a new file under the current umask."""
    return 0o666 & ~umask()


class TargetError(OSError):
    """An OSError met while writing one target; `target` is the file the user asked for."""

    def __init__(self, target: Path, err: OSError):
        super().__init__(err.errno, err.strerror or str(err), err.filename)
        self.target = target


@contextmanager
def atomic_paths(paths: Iterable[str | os.PathLike], suffix: str = "", exists: bool = True) -> Iterator[dict[Path, Path]]:
    """Temporary paths beside each target, `{target: temporary}`, for files written by libraries
    (matplotlib, fpdf, a CSV writer, h5py...). When the block ends without an exception all are
    renamed into place together, else all are removed. `suffix` ends the temporary names (for
    writers that pick the format from the name, e.g. ".png"). `exists=False`: the temporary names
    are reserved, then freed, for writers that refuse an existing file (a session writer). An
    OSError of ours is a TargetError."""
    temps: dict[Path, Path] = {}
    try:
        for path in map(Path, paths):
            try:
                fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{suffix}", dir=path.parent)
            except OSError as err:
                raise TargetError(path, err) from err
            os.close(fd)
            temps[path] = Path(tmp)
            if not exists:
                os.unlink(tmp)
        yield dict(temps)
        mode = file_mode()
        for path, tmp in temps.items():
            try:
                os.chmod(tmp, mode)
                os.replace(tmp, path)
            except OSError as err:
                raise TargetError(path, err) from err
        for folder in {p.parent for p in temps}:
            _fsync_folder(folder)
    finally:
        for tmp in temps.values():
            tmp.unlink(missing_ok=True)


def _fsync_folder(folder: Path) -> None:
    """Make the renames durable (a power cut keeps the new name); best effort."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_files_atomic(files: Mapping[str | os.PathLike, bytes | str], encoding: str = "utf-8") -> list[Path]:
    """Write every file or none (str is encoded, no newline translation), fsynced before the rename."""
    with atomic_paths(files) as temps:
        for (target, data), tmp in zip(files.items(), temps.values()):
            raw = data.encode(encoding) if isinstance(data, str) else bytes(data)
            try:
                with open(tmp, "wb") as fh:
                    fh.write(raw)
                    fh.flush()
                    os.fsync(fh.fileno())
            except OSError as err:
                raise TargetError(Path(target), err) from err
    return [Path(p) for p in files]
