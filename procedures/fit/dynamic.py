"""Static error from on-the-fly data: remove the speed-dependent part.

An on-the-fly reading (docs/onthefly.md) is taken while the leg moves at speed v (signed mm/s,
`speed_mm_s`). Besides the static error the table must hold it carries a dynamic offset: the
leg end lags the motor encoder that fires the position compare (servo and screw wind-up, the
laser's trigger latency), proportional to the speed and different in each direction:

    error_um(x, d, v) = static_um(x, d) + k_d * v          (k_d in um per mm/s)

The static part is what a stop-and-go reading sees after the dwell (v = 0). Every pass also
carries an offset of its own (re-zeroing, the laser, the warm-up of a screw that a fast pass
heats in seconds), so pass means alone cannot tell speed from offset well: an error of 0.003 um
per mm/s in `k_d` is 0.045 um at 15 mm/s, as large as the noise floor. Hence the anchor: each
on-the-fly pass ends at rest beyond its last target and takes one averaged static reading there
(FLAG_ANCHOR), which shares the pass's offset. For pass j

    anchor_j - mean_i(error_ij) = [static_d(x_end) - mean_i static_d(x_i)] - k_d * v_j

where the bracket is the same for every pass of direction d and the offset has cancelled: `k_d`
is minus the slope of that difference over the pass speeds (two speeds or more). Without
anchors (data from elsewhere) the pass means themselves are regressed on speed (and on time with
four passes or more, so a slow drift is not taken for speed), with the offset's uncertainty.
The static estimate of every
reading is then `error_um - k_d * v`: extrapolation to zero speed, one coefficient per leg and
direction, so it adds hardly any noise (a per-position extrapolation from two speeds would
multiply the noise by sqrt(5) at 10 and 20 mm/s).

Stop-and-go readings (speed NaN or 0) are left as they are; anchors are dropped once used (they
lie beyond the stroke of the table), and so are reversal probes (their use is the reversal,
procedures/fit/reversal_probes.py; in the fit, the noise floor or ISO 230-2 figures they would
count as passes of one reading).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from procedures.vocabulary import InputError
from procedures.io.recording.schema import FLAG_ANCHOR, FLAG_PROBE


@dataclass(frozen=True)
class SpeedCoefficient:
    """The dynamic error per unit speed of one leg and direction, um per mm/s, with its standard
    error, from `passes` passes at `speeds_mm_s` (distinct |speeds|); `anchored`: estimated from
    the passes' anchors (else from pass means)."""

    leg: int
    direction: int
    um_per_mm_s: float
    stderr_um_per_mm_s: float
    passes: int
    speeds_mm_s: tuple[float, ...]
    anchored: bool = False


def is_onthefly(points: np.ndarray) -> bool:
    """Whether any point of `points` was latched while moving (a finite, non-zero speed)."""
    names = points.dtype.names or ()
    if "speed_mm_s" not in names or len(points) == 0:
        return False
    v = np.asarray(points["speed_mm_s"], dtype=float)
    return bool(np.any(np.isfinite(v) & (v != 0)))


def speed_coefficients(points: np.ndarray, source: str = "the session") -> dict[tuple[int, int], SpeedCoefficient]:
    """`k_d` per (leg, direction) of the moving points of `points` (module docstring).
    InputError naming the leg and direction when its passes do not cover two speeds."""
    v_all = np.asarray(points["speed_mm_s"], dtype=float)
    moving = np.isfinite(v_all) & (v_all != 0) & np.isfinite(np.asarray(points["error_um"], dtype=float))
    anchors = points[(np.asarray(points["flags"]) & FLAG_ANCHOR) != 0]
    p = points[moving]
    out: dict[tuple[int, int], SpeedCoefficient] = {}
    for leg in sorted({int(x) for x in p["leg"]}):
        for d in (1, -1):
            sel = (p["leg"] == leg) & (p["direction"] == d)
            if not np.any(sel):
                continue
            q = p[sel]
            runs = np.unique(q["run"])
            # pass means over the positions every pass of this direction has (the same targets)
            common = None
            for r in runs:
                t = set(np.round(q["target_mm"][q["run"] == r], 6).tolist())
                common = t if common is None else common & t
            keep = np.isin(np.round(q["target_mm"], 6), sorted(common or ()))
            anchor_of = {int(a["run"]): float(a["error_um"]) for a in anchors
                         if int(a["leg"]) == leg and int(a["direction"]) == d and np.isfinite(a["error_um"])}
            anchored = all(int(r) in anchor_of for r in runs)
            m, v, t = [], [], []
            for r in runs:
                rs = keep & (q["run"] == r)
                if not np.any(rs):
                    continue
                mean = float(np.mean(q["error_um"][rs]))
                # anchored: minus (anchor - mean) = k v - bracket, the pass offset cancelled
                m.append(mean - anchor_of[int(r)] if anchored else mean)
                v.append(float(np.mean(q["speed_mm_s"][rs])))
                t.append(float(np.nanmean(q["time_s"][rs])) if np.any(np.isfinite(q["time_s"][rs])) else 0.0)
            speeds = tuple(sorted({round(abs(x), 1) for x in v}))
            if len(speeds) < 2:
                raise InputError(
                    f"{source}: leg {leg} direction {d:+d}: the on-the-fly passes ran at one speed only "
                    f"({speeds[0] if speeds else '?'} mm/s); the speed-dependent error needs passes at two speeds "
                    "(use plan onthefly, which alternates two)")
            m_a, v_a, t_a = np.array(m), np.array(v), np.array(t)
            cols = [np.ones_like(v_a), v_a]
            if not anchored and len(m) >= 4 and np.ptp(t_a) > 0:
                cols.append((t_a - t_a.mean()) / max(np.ptp(t_a), 1e-9))
            X = np.stack(cols, axis=1)
            coef, *_ = np.linalg.lstsq(X, m_a, rcond=None)
            dof = len(m) - X.shape[1]
            if dof > 0:
                resid = m_a - X @ coef
                s2 = float(resid @ resid) / dof
                cov = s2 * np.linalg.pinv(X.T @ X)
                se = float(np.sqrt(max(cov[1, 1], 0.0)))
            else:
                se = float("nan")
            out[(leg, d)] = SpeedCoefficient(leg, d, float(coef[1]), se, len(m), speeds, anchored)
    return out


def static_points(points: np.ndarray, source: str = "the session",
                  coefficients: dict[tuple[int, int], SpeedCoefficient] | None = None) -> np.ndarray:
    """A copy of `points` with the speed-dependent part removed from every moving reading:
    `error_um - k_d * speed_mm_s` (and `measured_mm` alike). Stop-and-go points unchanged.
    The result feeds the ordinary fit, noise floor and ISO 230-2 evaluation."""
    out = np.array(points, copy=True)
    if not is_onthefly(points):
        return out
    # anchors and reversal probes (static readings beside the passes) have done their work
    out = out[(np.asarray(out["flags"]) & (FLAG_ANCHOR | FLAG_PROBE)) == 0]
    coeffs = coefficients if coefficients is not None else speed_coefficients(points, source)
    v = np.asarray(out["speed_mm_s"], dtype=float)
    moving = np.isfinite(v) & (v != 0)
    for (leg, d), c in coeffs.items():
        sel = moving & (out["leg"] == leg) & (out["direction"] == d)
        corr_um = c.um_per_mm_s * v[sel]
        out["error_um"][sel] = out["error_um"][sel] - corr_um
        out["measured_mm"][sel] = out["measured_mm"][sel] - corr_um / 1000.0
    return out


def describe(coeffs: dict[tuple[int, int], SpeedCoefficient]) -> list[str]:
    """One line per leg and direction, for reports."""
    return [f"leg {c.leg} direction {c.direction:+d}: dynamic error {c.um_per_mm_s:+.4f} um per mm/s "
            f"(+/- {c.stderr_um_per_mm_s:.4f}; {c.passes} passes at {', '.join(f'{s:g}' for s in c.speeds_mm_s)} mm/s, "
            f"{'from their anchors' if c.anchored else 'from pass means'})"
            for c in coeffs.values()]
