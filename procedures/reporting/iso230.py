"""ISO 230-2 positioning accuracy of a leg from its recorded points (docs/iso230.md).

Deviation x_ij = measured - target = `error_um` of approach j to target i, micrometres.
Per target and direction: mean x_i(up|down) and estimator s_i (sample standard deviation,
n - 1 in the denominator). Up = direction +1 (approached while the position increased).

    B_i = x_i(up) - x_i(down)             B = max |B_i|            B_mean = mean B_i
    x_i = (x_i(up) + x_i(down)) / 2       M = max x_i - min x_i
    R_i(d) = 4 s_i(d)                     R(d) = max R_i(d)
    R_i = max(2 s_i(up) + 2 s_i(down) + |B_i|, R_i(up), R_i(down))     R = max R_i
    E(d) = max x_i(d) - min x_i(d)        E = max over both directions - min over both
    A(d) = max(x_i(d) + 2 s_i(d)) - min(x_i(d) - 2 s_i(d))   A likewise over both directions

A value that cannot be computed is None with a reason saying why (never NaN): bidirectional
values need the same targets in both directions; s needs at least 2 approaches per target and
direction (ISO 230-2 asks for 5: fewer is computed, with a note).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

ISO_APPROACHES = 5  # per target and direction
ISO_MIN_TARGETS = 5
TARGET_TOLERANCE_MM = 0.001  # targets closer than this are the same position (1 um)
OUTLIER_R_SHARE = 0.5  # a run is noted when R of its direction without it is below this share

UNI = ("E", "A", "R")
BI_NAMES = ("E", "M", "A", "B", "B_mean", "R")
VALUE_NAMES = ("E", "E_up", "E_down", "M", "A", "A_up", "A_down", "B", "B_mean", "R", "R_up", "R_down")
"""Keys of LegIso230.values, micrometres."""


@dataclass(frozen=True)
class TargetStats:
    """Statistics at one target position for one direction (um)."""

    target_mm: float
    n: int
    mean_um: float
    s_um: float | None  # None with fewer than 2 approaches


@dataclass(frozen=True)
class LegIso230:
    """ISO 230-2 values of one leg, micrometres.

    `values[name]` for name in VALUE_NAMES is a float or None; `reasons[name]` says why a value
    is None. `notes` are warnings about values that were computed (too few approaches, a run
    far off the others, ...). `up` / `down` hold the per-target statistics.
    """

    leg: int
    values: dict[str, float | None]
    reasons: dict[str, str]
    notes: list[str]
    up: list[TargetStats]
    down: list[TargetStats]
    n_points: int
    skipped_points: int = 0

    @property
    def n_targets(self) -> int:
        return max(len(self.up), len(self.down))

    @property
    def n_cycles(self) -> int:
        """Fewest approaches at any target in either direction present (0 without points)."""
        counts = [t.n for t in self.up + self.down]
        return min(counts) if counts else 0

    def __getitem__(self, name: str) -> float | None:
        return self.values[name]


def _cluster_targets(targets_mm: np.ndarray) -> list[np.ndarray]:
    """Indices into `targets_mm` grouped by position (neighbours within TARGET_TOLERANCE_MM)."""
    order = np.argsort(targets_mm, kind="stable")
    groups: list[list[int]] = []
    last = None
    for i in order:
        t = targets_mm[i]
        if last is None or t - last > TARGET_TOLERANCE_MM:
            groups.append([])
        groups[-1].append(int(i))
        last = t
    return [np.asarray(g) for g in groups]


def _direction_stats(pts: np.ndarray) -> tuple[list[TargetStats], list[np.ndarray]]:
    groups = _cluster_targets(pts["target_mm"])
    stats = []
    for g in groups:
        x = pts["error_um"][g]
        s = float(np.std(x, ddof=1)) if len(x) >= 2 else None
        stats.append(TargetStats(float(np.mean(pts["target_mm"][g])), len(x), float(np.mean(x)), s))
    return stats, groups


def _fmt_mm(v: float) -> str:
    return f"{v:.6g}"


def _uni_values(stats: list[TargetStats], word: str) -> tuple[dict[str, float | None], dict[str, str]]:
    values: dict[str, float | None] = {}
    reasons: dict[str, str] = {}
    if not stats:
        for name in UNI:
            values[name], reasons[name] = None, f"no approaches in the {word} direction"
        return values, reasons
    means = [t.mean_um for t in stats]
    if len(stats) < 2:
        values["E"] = None
        reasons["E"] = f"only one target position in the {word} direction; E needs at least 2"
    else:
        values["E"] = max(means) - min(means)
    few = [t for t in stats if t.s_um is None]
    if few:
        where = ", ".join(f"{_fmt_mm(t.target_mm)} mm" for t in few[:5]) + (" ..." if len(few) > 5 else "")
        why = (f"{len(few)} of {len(stats)} {word} targets have a single approach ({where}); the estimator s "
               f"needs at least 2 approaches per target (ISO 230-2: {ISO_APPROACHES})")
        for name in ("A", "R"):
            values[name], reasons[name] = None, why
    else:
        values["R"] = max(4 * t.s_um for t in stats)
        values["A"] = max(t.mean_um + 2 * t.s_um for t in stats) - min(t.mean_um - 2 * t.s_um for t in stats)
    return values, reasons


def _match_reason(up: list[TargetStats], down: list[TargetStats]) -> str | None:
    """Why the forward and backward targets cannot be paired, or None when they match."""
    names = "bidirectional values (B, M, R, E, A) need the same targets in both directions"
    if len(up) != len(down):
        return (f"forward approaches reach {len(up)} target positions and backward ones {len(down)}: {names}")
    diffs = np.array([abs(u.target_mm - d.target_mm) for u, d in zip(up, down)])
    bad = diffs > TARGET_TOLERANCE_MM
    if not bad.any():
        return None
    lo, hi = float(diffs[bad].min()), float(diffs[bad].max())
    by = f"{lo:.3g} mm" if f"{lo:.3g}" == f"{hi:.3g}" else f"{lo:.3g} to {hi:.3g} mm"
    return f"backward targets differ from forward targets by {by} at {int(bad.sum())} of {len(up)} positions: {names}"


def _outlier_notes(pts: np.ndarray) -> list[str]:
    """Runs that alone make up most of a direction's repeatability (informative only).

    For each run, R of its direction is recomputed without it; when that more than halves R,
    the run is far off the others (a disturbed cycle, a re-zeroed laser) and worth a look.
    """
    notes = []
    for d, word in ((1, "up"), (-1, "down")):
        sel = pts[pts["direction"] == d]
        groups = _cluster_targets(sel["target_mm"])
        if not groups or min(len(g) for g in groups) < 3:
            continue  # without a run some target would keep fewer than 2 approaches
        r_with = max(4 * float(np.std(sel["error_um"][g], ddof=1)) for g in groups)
        for run in np.unique(sel["run"]):
            keep = [g[sel["run"][g] != run] for g in groups]
            if min(len(k) for k in keep) < 2:
                continue
            r_without = max(4 * float(np.std(sel["error_um"][k], ddof=1)) for k in keep)
            if r_with > 0 and r_without < OUTLIER_R_SHARE * r_with:
                notes.append(
                    f"run {int(run)} (direction {d:+d}) is far off the other approaches: without it R_{word} would "
                    f"be {r_without:.4g} um instead of {r_with:.4g} um; values include it, check that cycle"
                )
    return notes


def evaluate_leg(points: np.ndarray, leg: int) -> LegIso230:
    """ISO 230-2 values of `leg` from POINT_DTYPE rows (other legs' rows are ignored)."""
    pts_all = points[points["leg"] == leg]
    known = np.isfinite(pts_all["error_um"]) & np.isfinite(pts_all["target_mm"])
    pts = pts_all[known]
    skipped = int(np.count_nonzero(~known))
    notes: list[str] = []
    if skipped:
        notes.append(f"{skipped} points without a measured error were left out")
    up, _ = _direction_stats(pts[pts["direction"] == 1])
    down, _ = _direction_stats(pts[pts["direction"] == -1])
    values: dict[str, float | None] = {}
    reasons: dict[str, str] = {}
    for stats, suffix, word in ((up, "_up", "positive"), (down, "_down", "negative")):
        v, r = _uni_values(stats, word)
        for name in UNI:
            values[name + suffix] = v[name]
            if name in r:
                reasons[name + suffix] = r[name]

    if not up or not down:
        why = (f"approaches in only one direction ({'positive' if up else 'negative'}); bidirectional values "
               "need both") if (up or down) else "no measured points"
        for name in BI_NAMES:
            values[name], reasons[name] = None, why
    else:
        mismatch = _match_reason(up, down)
        if mismatch:
            for name in BI_NAMES:
                values[name], reasons[name] = None, mismatch
        else:
            b = [u.mean_um - d.mean_um for u, d in zip(up, down)]
            xbar = [(u.mean_um + d.mean_um) / 2 for u, d in zip(up, down)]
            values["B"] = max(abs(v) for v in b)
            values["B_mean"] = sum(b) / len(b)
            if len(up) < 2:
                values["M"] = values["E"] = None
                reasons["M"] = reasons["E"] = "only one target position; M and E need at least 2"
            else:
                values["M"] = max(xbar) - min(xbar)
                means = [t.mean_um for t in up + down]
                values["E"] = max(means) - min(means)
            if any(t.s_um is None for t in up + down):
                why = (f"some targets have a single approach in a direction; R and A need the estimator s at "
                       f"every target in both directions (ISO 230-2: {ISO_APPROACHES} approaches)")
                values["R"] = values["A"] = None
                reasons["R"] = reasons["A"] = why
            else:
                values["R"] = max(
                    max(2 * u.s_um + 2 * d.s_um + abs(bi), 4 * u.s_um, 4 * d.s_um) for u, d, bi in zip(up, down, b)
                )
                both = up + down
                values["A"] = max(t.mean_um + 2 * t.s_um for t in both) - min(t.mean_um - 2 * t.s_um for t in both)

    counts = [t.n for t in up + down]
    if counts:
        lo, hi = min(counts), max(counts)
        if lo < ISO_APPROACHES:
            notes.append(f"ISO 230-2 asks for {ISO_APPROACHES} approaches per target and direction; found "
                         f"{lo if lo == hi else f'{lo} to {hi}'} (values computed, less reliable)")
        elif lo != hi:
            notes.append(f"approach counts differ between targets ({lo} to {hi})")
        n_t = max(len(up), len(down))
        if n_t < ISO_MIN_TARGETS:
            notes.append(f"ISO 230-2 asks for at least {ISO_MIN_TARGETS} target positions; found {n_t}")
        notes.extend(_outlier_notes(pts))
    values = {name: values.get(name) for name in VALUE_NAMES}
    for name, v in values.items():  # a guard: no NaN may leave this module
        if v is not None and not math.isfinite(v):
            values[name], reasons[name] = None, "not finite (a bug: please report the file)"
    return LegIso230(leg=int(leg), values=values, reasons=reasons, notes=notes, up=up, down=down,
                     n_points=len(pts), skipped_points=skipped)


def evaluate(points: np.ndarray) -> dict[int, LegIso230]:
    """ISO 230-2 values per leg (leg number -> LegIso230) from POINT_DTYPE rows, micrometres.

    Uses `leg`, `direction`, `target_mm` and `error_um` (measured - target); runs and order do
    not matter. Points without a measured error are left out (and noted). A session's on-the-fly
    readings are judged on their static part, its anchors and reversal probes left out
    (procedures.fit.dynamic.static_points, as `station fit` and `station verify` take them).
    """
    from procedures.fit.dynamic import is_onthefly, static_points  # the fit package imports this one

    pts = np.asarray(points)
    if len(pts) and is_onthefly(pts):
        pts = static_points(pts)
    return {int(leg): evaluate_leg(pts, int(leg)) for leg in np.unique(pts["leg"])}


def _targets_json(r: LegIso230) -> list[dict[str, Any]]:
    rows = []
    for word, stats in (("up", r.up), ("down", r.down)):
        for t in stats:
            rows.append({"direction": word, "target_mm": t.target_mm, "n": t.n, "mean_um": t.mean_um,
                         "s_um": t.s_um})
    return rows


def to_json(results: dict[int, LegIso230], source: dict[str, Any] | None = None) -> dict[str, Any]:
    """JSON-able dict: {"legs": {"1": {"E": .., "E_up": .., ..., "R_down": .., "n_targets": ..,
    "n_cycles": .., "notes": [..], "not_computed": {name: reason}, "targets": [..]}}} in um;
    `source` (e.g. {"path": .., "sha256": ..}) names the recording the values came from.
    """
    out: dict[str, Any] = {"standard": "ISO 230-2", "units": "um"}
    if source:
        out["source"] = source
    legs = {}
    for leg in sorted(results):
        r = results[leg]
        entry: dict[str, Any] = dict(r.values)
        entry.update(n_targets=r.n_targets, n_cycles=r.n_cycles, n_points=r.n_points, notes=list(r.notes),
                     not_computed=dict(r.reasons), targets=_targets_json(r))
        legs[str(leg)] = entry
    out["legs"] = legs
    return out


def dumps(results: dict[int, LegIso230], source: dict[str, Any] | None = None) -> str:
    """to_json as text; allow_nan=False guarantees no NaN ever reaches a file."""
    return json.dumps(to_json(results, source), indent=2, allow_nan=False)


_ROWS = (
    ("E", "systematic positional deviation"),
    ("A", "accuracy"),
    ("R", "repeatability"),
    ("M", "range of mean bidirectional deviation"),
    ("B", "reversal value (max |B_i|)"),
    ("B_mean", "mean reversal value"),
)
MEANINGS: dict[str, str] = dict(_ROWS)
"""The name of each ISO 230-2 value, as `station iso230` and `station report` print it."""


def format_table(results: dict[int, LegIso230]) -> str:
    """A readable table per leg (um), with notes and the reason for every value not computed."""
    lines: list[str] = []
    for leg in sorted(results):
        r = results[leg]
        lines.append(f"Leg {leg}: ISO 230-2, {r.n_targets} targets, {r.n_cycles} approaches per target and "
                     f"direction (fewest), {r.n_points} points; values in um")
        lines.append(f"  {'':6} {'up':>10} {'down':>10} {'both':>10}   meaning")

        def cell(name: str) -> str:
            v = r.values.get(name)
            return f"{v:10.4f}" if v is not None else f"{'-':>10}"

        for name, meaning in _ROWS:
            if name in UNI:
                lines.append(f"  {name:6} {cell(name + '_up')} {cell(name + '_down')} {cell(name)}   {meaning}")
            else:
                lines.append(f"  {name:6} {'':10} {'':10} {cell(name)}   {meaning}")
        by_reason: dict[str, list[str]] = {}
        for name in VALUE_NAMES:
            if name in r.reasons:
                by_reason.setdefault(r.reasons[name], []).append(name)
        for reason, names in by_reason.items():
            lines.append(f"  not computed ({', '.join(names)}): {reason}")
        for note in r.notes:
            lines.append(f"  note: {note}")
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"
