"""Where a job writes, checked before it moves anything or computes for long: one rule for every
output of every front end (issue 22, item 4).

- An output that exists is refused, naming it, unless the user said `force` (`--force`).
- The folder it goes into must exist (nothing is created behind the user's back: a folder
  output is created itself, never its parents, as a file's folder is never made) and must take a new file: a real file is created there and
  removed again, so a read-only folder, a full or read-only file system, or a folder only root
  could write (for a user who is not root) are all told apart from a good one by the system
  itself, not by guessing from permission bits.

Each check raises InputError, one line naming the option, the path and what to do; nothing is
left behind by the check itself.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from procedures.vocabulary import InputError

NOTHING_WRITTEN = "nothing was written"


def _probe(folder: Path, option: str, path: Path) -> None:
    """InputError unless a file can be created in `folder` (created and removed at once)."""
    try:
        fd, name = tempfile.mkstemp(prefix=".station-write-check-", dir=folder)
    except OSError as exc:
        why = (exc.strerror or str(exc)).lower()
        raise InputError(f"{option} {path}: the folder {folder} cannot be written ({why}); choose another "
                         f"{option} or make the folder writable; {NOTHING_WRITTEN}") from None
    os.close(fd)
    os.unlink(name)


def _existing_ancestor(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def check_output_file(path: str | Path, *, force: bool = False, option: str = "--out",
                      suffixes: tuple[str, ...] = (), make_parents: bool = False) -> Path:
    """`path` as a Path once it can be written: not there (or `force`), not a folder, of one of
    `suffixes` (when given, e.g. (".h5",)), its folder there (or `make_parents`: its nearest
    existing ancestor) and writable. InputError (one line) otherwise."""
    p = Path(path)
    if suffixes and p.suffix.lower() not in suffixes:
        written_as = {".h5": "HDF5, a session file"}.get(suffixes[0], suffixes[0][1:].upper())
        raise InputError(f"{option} {p}: must end in {' or '.join(suffixes)} (the file is written as "
                         f"{written_as}); {NOTHING_WRITTEN}")
    if p.is_dir():
        raise InputError(f"{option} {p}: is a folder; give a file name; {NOTHING_WRITTEN}")
    if p.exists() and not force:
        raise InputError(f"{option} {p}: exists; add --force to replace it, or choose another {option}; "
                         f"{NOTHING_WRITTEN}")
    folder = p.parent
    if not folder.is_dir():
        if not make_parents:
            raise InputError(f"{option} {p}: the folder {folder} does not exist; create it first or choose "
                             f"another {option}; {NOTHING_WRITTEN}")
        folder = _existing_ancestor(folder)
        if not folder.is_dir():
            raise InputError(f"{option} {p}: {folder} is a file, not a folder; {NOTHING_WRITTEN}")
    _probe(folder, option, p)
    return p


def check_output_folder(path: str | Path, *, force: bool = False, option: str = "--out") -> Path:
    """`path` as a Path once a folder of results can be written there: not there (its parent
    there and writable; the writer creates the folder, never its parents: `report --out
    missing/sub` is refused as `fit --out missing/m.json` is), or there and `force` (then writable
    itself). InputError (one line) otherwise."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{option} {p}: is a file; give a folder; {NOTHING_WRITTEN}")
    if p.is_dir():
        if not force:
            raise InputError(f"{option} {p}: exists; add --force to replace what it holds, or choose another "
                             f"{option}; {NOTHING_WRITTEN}")
        _probe(p, option, p)
        return p
    if not p.parent.is_dir():
        what = "is a file, not a folder" if p.parent.exists() else "does not exist"
        raise InputError(f"{option} {p}: the folder {p.parent} {what}; create it first or choose another "
                         f"{option}; {NOTHING_WRITTEN}")
    _probe(p.parent, option, p)
    return p


def check_appendable(path: str | Path, option: str = "--resume") -> Path:
    """`path`, an existing file a job appends to (a resumed session), once it can be opened for
    writing (opened and closed, nothing written). InputError (one line) otherwise."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{option} {p}: no such file; give the session file to finish")
    try:
        with open(p, "r+b"):
            pass
    except OSError as exc:
        raise InputError(f"{option} {p}: cannot be written ({(exc.strerror or str(exc)).lower()}); make it "
                         f"writable or copy it somewhere writable first; {NOTHING_WRITTEN}") from None
    return p
