"""How a replayed session differs from its recording (`station replay`, the terminal UI's replay):
every point field, every fault and the outcome, compared over the two session files' contents."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from procedures.io.recording.reader import Session
from procedures.io.recording.schema import FLAG_REPLAYED


@dataclass(frozen=True)
class Comparison:
    """How a replayed session differs from its recording. `differences` is empty when every
    point field (flags apart from FLAG_REPLAYED), every fault and the outcome are identical."""

    points: int
    faults: int
    differences: tuple[str, ...]

    @property
    def identical(self) -> bool:
        return not self.differences


def _same(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Element-wise bit-identity, NaN equal to NaN (an unknown value stays unknown)."""
    if a.dtype.kind == "f":
        return (a == b) | (np.isnan(a) & np.isnan(b))
    return a == b


def compare_sessions(original: Session, replayed: Session) -> Comparison:
    """Compare a replay with its recording point by point (matched by plan index)."""
    diffs: list[str] = []
    po, pr = original.points, replayed.points
    if len(po) != len(pr):
        diffs.append(f"{len(pr)} points replayed, the recording has {len(po)}")
    o = po[np.argsort(po["index"], kind="stable")]
    r = pr[np.argsort(pr["index"], kind="stable")]
    n = min(len(o), len(r))
    o, r = o[:n], r[:n]
    for name in po.dtype.names:
        a, b = o[name], r[name]
        if name == "flags":
            a = a | FLAG_REPLAYED
        bad = np.flatnonzero(~_same(a, b))
        if bad.size:
            i = int(bad[0])
            diffs.append(f"{name} differs at {bad.size} point(s), first at index {int(o['index'][i])}: "
                         f"recorded {a[i]!r}, replayed {b[i]!r}")
    fo, fr = original.faults, replayed.faults
    keys = ("index", "leg", "run", "target_mm", "time_s", "kind", "attempt", "gave_up")
    if len(fo) != len(fr):
        diffs.append(f"{len(fr)} faults replayed, the recording has {len(fo)}")
    for i, (a, b) in enumerate(zip(fo, fr)):
        bad = [k for k in keys if not bool(_same(np.asarray(a[k]), np.asarray(b[k])))]
        if bad:
            diffs.append(f"fault {i} differs in {', '.join(bad)}")
            break
    # a killed session ("incomplete") replays to where it ends and is aborted there
    if original.outcome != replayed.outcome and (original.outcome, replayed.outcome) != ("incomplete", "aborted"):
        diffs.append(f"outcome {replayed.outcome!r}, the recording's was {original.outcome!r}")
    return Comparison(len(pr), len(fr), tuple(diffs))
