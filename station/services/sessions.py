"""Where sessions are recorded: the one place new session file names are made, for every front end."""

from __future__ import annotations

import time
from pathlib import Path

from station.services.config import StationConfig


def _unused(base: Path) -> Path:
    """`base`, or its first "-N" sibling (N = 2, 3, ...) that does not exist."""
    out, n = base, 1
    while out.exists():
        n += 1
        out = base.with_name(f"{base.stem}-{n}{base.suffix}")
    return out


def default_session_path(cfg: StationConfig, legs: tuple[int, ...] | None = None, prefix: str = "ui") -> Path:
    """RECORDINGS/PREFIX-YYYYmmdd-HHMMSS-leg1-2.h5 under the config's recordings folder (without
    `legs`: no leg tag), "-2", "-3", ... appended while the name is taken: a new session never
    overwrites one."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    tag = "" if legs is None else "-leg" + "-".join(str(leg) for leg in legs)
    return _unused(Path(cfg.recordings_dir) / f"{prefix}-{stamp}{tag}.h5")


def replay_output_path(cfg: StationConfig, source: Path) -> Path:
    """RECORDINGS/NAME.replay.h5 (then -2, -3, ...): a replay never overwrites a session."""
    base = Path(cfg.recordings_dir) / f"{source.stem}.replay.h5"
    out, n = base, 1
    while out.exists() or out.resolve() == source.resolve():
        n += 1
        out = base.with_name(f"{source.stem}.replay-{n}.h5")
    return out


def new_session_problem(out: Path) -> str:
    """'' when a new session may be recorded to `out`; "exists" when the file is there already
    (a session is never overwritten: resume it or choose another name); "no folder" when its
    folder does not exist (nothing is created behind the operator's back)."""
    if out.exists():
        return "exists"
    if not out.parent.is_dir():
        return "no folder"
    return ""
