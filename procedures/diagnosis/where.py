"""Where the gap lies: a breakdown of one leg's gap (measured minus twin, um).

By direction, stroke region, pass and time, position frequency (with the screw lead marked) and
by condition (material temperature, load) when recorded; the variance of the gap split into a
constant offset, a direction part, a pass-to-pass part, a position part and the rest; and the
dominant locus named in words.
"""

from __future__ import annotations

import numpy as np

from procedures.diagnosis.aliasing import sampling_warning
from procedures.diagnosis.effects import cyclic_grid
from procedures.diagnosis.legdata import LegData
from procedures.diagnosis.twin import sinusoid_scan


def _rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(v**2))) if v.size else 0.0


def _stats(v: np.ndarray) -> dict:
    return {"points": int(v.size), "mean_um": float(v.mean()), "rms_um": _rms(v), "p2p_um": float(np.ptp(v))}


def _line(x: np.ndarray, y: np.ndarray) -> tuple[float, float] | None:
    """Slope of y on x and the correlation; None when x does not vary."""
    if x.size < 3 or np.ptp(x) <= 0 or not np.all(np.isfinite(x)):
        return None
    xc, yc = x - x.mean(), y - y.mean()
    slope = float(xc @ yc / (xc @ xc))
    den = float(np.sqrt((xc @ xc) * (yc @ yc)))
    return slope, (float(xc @ yc / den) if den > 0 else 0.0)


def _region_name(i: int, n: int) -> str:
    if n == 4:
        return ("the bottom of the stroke", "the lower middle of the stroke", "the upper middle of the stroke",
                "the top of the stroke")[i]
    if n == 3:
        return ("the bottom of the stroke", "the middle of the stroke", "the top of the stroke")[i]
    return f"region {i + 1} of {n}"


def spectrum(leg: LegData, gap_um: np.ndarray, lead_mm: float | None, pass_means: np.ndarray,
             motor_turn_mm: float | None = None) -> dict:
    """Peaks of the least-squares sinusoid scan of the per-position mean gap (pass offsets
    removed), each with a sampling warning when it may be an alias (aliasing.py), and the
    amplitude at the screw lead."""
    lo, hi = leg.span_mm
    out: dict = {"peaks": [], "lead_mm": lead_mm}
    r = gap_um - pass_means[leg.pass_id]
    ux, inv = np.unique(leg.x_mm, return_inverse=True)
    w = np.bincount(inv).astype(float)
    m = np.bincount(inv, r) / w
    grid = cyclic_grid(leg, oversample=2)
    if grid.size == 0:
        out["note"] = f"only {leg.n_targets} distinct targets: no spectrum"
        out["lead_amplitude_um"] = None
        return out
    amp, _, _ = sinusoid_scan(ux, m - np.average(m, weights=w), w, grid)
    peaks = [i for i in range(grid.size) if (i == 0 or amp[i] >= amp[i - 1]) and (i == grid.size - 1 or amp[i] > amp[i + 1])]
    floor = float(np.median(amp))
    peaks = sorted((i for i in peaks if amp[i] > 3 * floor), key=lambda i: -amp[i])[:3]
    out["peaks"] = [{"wavelength_mm": float(1 / grid[i]), "amplitude_um": float(amp[i])} for i in peaks]
    for p in out["peaks"]:
        warn = sampling_warning(p["wavelength_mm"], leg.spacing_mm, hi - lo, lead_mm, motor_turn_mm)
        if warn:
            p["sampling"] = warn
    out["median_amplitude_um"] = floor
    if lead_mm:
        if lead_mm < 2 * leg.spacing_mm:
            out["lead_amplitude_um"] = None
            out["lead_note"] = (f"the {lead_mm:g} mm lead is shorter than twice the {leg.spacing_mm:.3g} mm target "
                                "spacing: it cannot be resolved (it aliases)")
        elif lead_mm > hi - lo:
            out["lead_amplitude_um"] = None
            out["lead_note"] = f"the {lead_mm:g} mm lead is longer than the measured stroke"
        else:
            a = float(sinusoid_scan(ux, m - np.average(m, weights=w), w, np.array([1 / lead_mm]))[0][0])
            out["lead_amplitude_um"] = a
            out["lead_is_peak"] = any(abs(1 / p["wavelength_mm"] - 1 / lead_mm) <= 1.5 / (2 * (hi - lo)) for p in out["peaks"])
    return out


def point_deviations(leg: LegData, gap_um: np.ndarray) -> np.ndarray:
    """Each point's gap minus its pass offset and minus the median of its (target, direction)
    cell: how far a point is from its repeats, um."""
    counts = np.bincount(leg.pass_id).astype(float)
    r0 = gap_um - (np.bincount(leg.pass_id, gap_um) / counts)[leg.pass_id]
    _, inv = np.unique(leg.target_id * 2 + (leg.direction > 0), return_inverse=True)
    return r0 - group_median(r0, inv)[inv]


def group_median(v: np.ndarray, group: np.ndarray) -> np.ndarray:
    """Median of `v` within each group 0..G-1 (vectorised: one sort)."""
    order = np.lexsort((v, group))
    sv = v[order]
    counts = np.bincount(group)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return 0.5 * (sv[starts + (counts - 1) // 2] + sv[starts + counts // 2])


def outlier_mask(leg: LegData, gap_um: np.ndarray, threshold_um: float) -> np.ndarray:
    """Points more than 6 robust standard deviations (and the threshold) from their repeats."""
    dev = point_deviations(leg, gap_um)
    scale = max(1.4826 * float(np.median(np.abs(dev))), 1e-3)
    return (np.abs(dev) > 6 * scale) & (np.abs(dev) > threshold_um)


def repeatability_um(leg: LegData, resid_um: np.ndarray, exclude: np.ndarray | None = None) -> float | None:
    """Pooled standard deviation of `resid_um` over repeat passes at the same target and
    direction (n - cells degrees of freedom), um, leaving out the points in `exclude`
    (outliers); None without repeats."""
    keep = np.ones(leg.n_points, dtype=bool) if exclude is None else ~exclude
    cell = (leg.target_id * 2 + (leg.direction > 0))[keep]
    r = resid_um[keep]
    ids, inv = np.unique(cell, return_inverse=True)
    cnt = np.bincount(inv).astype(float)
    mean = np.bincount(inv, r) / cnt
    dof = r.size - ids.size
    if dof <= 0:
        return None
    return float(np.sqrt(np.sum((r - mean[inv]) ** 2) / dof))


def by_target(leg: LegData, gap_um: np.ndarray) -> dict:
    """Mean gap per target and direction, um, against the target position, mm (None where a
    direction has no point at a target). JSON-able; the TUI plots it."""
    n_t = leg.targets_mm.size
    out: dict = {"position_mm": [float(x) for x in leg.targets_mm]}
    for d, key in ((1.0, "gap_up_um"), (-1.0, "gap_down_um")):
        sel = leg.direction == d
        counts = np.bincount(leg.target_id[sel], minlength=n_t)
        sums = np.bincount(leg.target_id[sel], gap_um[sel], minlength=n_t)
        out[key] = [float(sums[i] / counts[i]) if counts[i] else None for i in range(n_t)]
    return out


def outlier_passes(leg: LegData, threshold_um: float, explained_um: np.ndarray | None = None):
    """(outlier passes, passes explained by temperature). How far each pass lies from the median
    of its repeats (same target and direction), on the errors themselves so the twin cannot blur
    it, with the named effects (`explained_um`, um per point) taken out; robust scale over
    passes. A pass off the others only because the leg was colder or warmer then (the cold first
    pass of a warm-up) is not an outlier: when the material temperature is recorded, a line of
    pass offset against pass temperature fitted on the other passes that predicts it within the
    outlier limit explains it."""
    if leg.n_passes < 4:
        return [], []
    counts = np.bincount(leg.pass_id).astype(float)
    err = leg.error_um if explained_um is None else leg.error_um - explained_um
    _, cinv = np.unique(leg.target_id * 2 + (leg.direction > 0), return_inverse=True)
    from_repeats = err - group_median(err, cinv)[cinv]
    dev = np.bincount(leg.pass_id, from_repeats) / counts
    dev = dev - np.median(dev)
    scale = max(1.4826 * float(np.median(np.abs(dev))), 1e-3)
    limit = max(5 * scale, threshold_um)
    temp = np.bincount(leg.pass_id, leg.temp_c) / counts if leg.has_temp else None
    outliers, explained = [], []
    for p in range(leg.n_passes):
        if abs(dev[p]) <= limit:
            continue
        entry = {"run": int(leg.run[leg.pass_id == p][0]), "offset_um": float(dev[p])}
        if temp is not None:
            others = np.arange(leg.n_passes) != p
            line = _line(temp[others], dev[others])
            if line is not None:
                pred = float(np.mean(dev[others]) + line[0] * (temp[p] - np.mean(temp[others])))
                if abs(dev[p] - pred) <= limit:
                    explained.append({**entry, "temp_c": float(temp[p]), "predicted_um": pred, "um_per_k": line[0]})
                    continue
        outliers.append(entry)
    return outliers, explained


def breakdown(leg: LegData, gap_um: np.ndarray, external_twin: bool, lead_mm: float | None = 5.0,
              regions: int = 4, threshold_um: float = 0.1, scatter_um: float | None = None,
              explained_um: np.ndarray | None = None, motor_turn_mm: float | None = None) -> dict:
    """The where-report of one leg (JSON-able dict; units in the keys). `scatter_um` (the
    repeat scatter after effects), when known, lets the words say that a gap is no larger than
    the scatter of repeat passes; `explained_um` (the named effects at every point, um) is taken
    out before passes are called outliers."""
    g = gap_um
    n = g.size
    counts = np.bincount(leg.pass_id).astype(float)
    pass_means = np.bincount(leg.pass_id, g) / counts
    pass_dir = np.array([leg.direction[leg.pass_id == p][0] for p in range(leg.n_passes)])
    out: dict = {"gap": _stats(g)}
    # by direction
    by_dir = {}
    dir_mean = {}
    for d, key in ((1.0, "+1"), (-1.0, "-1")):
        sel = leg.direction == d
        if sel.any():
            by_dir[key] = _stats(g[sel])
            dir_mean[d] = float(g[sel].mean())
    out["by_direction"] = by_dir
    if len(dir_mean) == 2:
        out["direction_offset_um"] = dir_mean[-1.0] - dir_mean[1.0]  # negative minus positive, as reversal_um
    # by stroke region (equal lengths of the measured stroke)
    lo, hi = leg.span_mm
    edges = np.linspace(lo, hi, regions + 1)
    reg = np.clip(np.searchsorted(edges, leg.x_mm, side="right") - 1, 0, regions - 1)
    out["by_region"] = [
        {"from_mm": float(edges[i]), "to_mm": float(edges[i + 1]), **_stats(g[reg == i])}
        for i in range(regions) if np.any(reg == i)
    ]
    # by target and direction: the gap against position, what the engineer plots
    out["by_target"] = by_target(leg, g)
    # by pass and time
    times = [float(np.mean(leg.time_h[leg.pass_id == p]) * 3600.0) if leg.has_time else None for p in range(leg.n_passes)]
    out["by_pass"] = [
        {"run": int(leg.run[leg.pass_id == p][0]), "direction": int(pass_dir[p]), "time_mid_s": times[p],
         "mean_um": float(pass_means[p]), "rms_um": _rms(g[leg.pass_id == p])}
        for p in range(leg.n_passes)
    ]
    # pass offsets beyond the direction part: trend and outliers
    dm = np.array([dir_mean.get(d, 0.0) for d in pass_dir])
    pass_dev = pass_means - dm
    trend: dict = {}
    if leg.has_time:
        t_h = np.array([np.mean(leg.time_h[leg.pass_id == p]) for p in range(leg.n_passes)])
        line = _line(t_h, pass_dev)
        if line:
            trend = {"um_per_h": line[0], "r": line[1]}
    if not trend:
        line = _line(np.arange(leg.n_passes, dtype=float), pass_dev)
        if line:
            trend = {"um_per_pass": line[0], "r": line[1], "note": "no time recorded: trend against pass order"}
    out["pass_trend"] = trend or None
    out["outlier_passes"], explained = outlier_passes(leg, threshold_um, explained_um)
    if explained:
        out["passes_explained_by_temperature"] = explained
    dev = point_deviations(leg, g)
    bad = np.flatnonzero(outlier_mask(leg, g, threshold_um))
    worst = bad[np.argsort(-np.abs(dev[bad]))][:5]
    out["outlier_points"] = {
        "count": int(bad.size),
        "share_pct": 100.0 * float(np.sum(dev[bad] ** 2) / max(np.sum(g**2), 1e-300)),
        "worst": [{"run": int(leg.run[i]), "target_mm": float(leg.x_mm[i]), "deviation_um": float(dev[i])} for i in worst],
    }
    cell = leg.target_id * 2 + (leg.direction > 0)
    _, cell_inv = np.unique(cell, return_inverse=True)
    # by condition
    cond: dict = {}
    if leg.has_temp:
        tp = np.bincount(leg.pass_id, leg.temp_c) / counts
        line = _line(tp, pass_dev)
        cond["material_temp"] = {"range_k": float(np.ptp(leg.temp_c)),
                                 "um_per_k": line[0] if line else None, "r": line[1] if line else None}
        if not line:
            cond["material_temp"]["note"] = "the pass-mean temperature did not change"
    else:
        cond["material_temp"] = None
        cond["material_temp_note"] = "not recorded"
    if leg.has_load:
        lp = np.bincount(leg.pass_id, leg.load_kn) / counts
        line = _line(lp, pass_dev)
        cond["load"] = {"range_n": float(1000 * np.ptp(leg.load_kn)),
                        "um_per_kn": line[0] if line else None, "r": line[1] if line else None}
        if not line:
            cond["load"]["note"] = "the load did not change between passes"
    else:
        cond["load"] = None
        cond["load_note"] = "not recorded"
    out["by_condition"] = cond
    out["spectrum"] = spectrum(leg, g, lead_mm, pass_means, motor_turn_mm)
    # variance shares (mean squares about zero, sequential: offset, direction, pass, position, rest)
    total = float(np.mean(g**2))
    mean = float(g.mean())
    d_part = np.array([dir_mean.get(d, mean) for d in leg.direction]) - mean
    p_part = pass_means[leg.pass_id] - mean - d_part
    r1 = g - pass_means[leg.pass_id]
    tcount = np.bincount(leg.target_id).astype(float)
    pos_part = (np.bincount(leg.target_id, r1) / np.maximum(tcount, 1))[leg.target_id]
    r2 = r1 - pos_part
    # direction-dependent shape: what the (target, direction) means add beyond the target means
    ccount = np.bincount(cell_inv).astype(float)
    dpos_part = (np.bincount(cell_inv, r2) / ccount)[cell_inv]
    rest = r2 - dpos_part
    parts = {"offset": mean**2, "direction": float(np.mean(d_part**2)), "pass": float(np.mean(p_part**2)),
             "position": float(np.mean(pos_part**2)), "direction_by_position": float(np.mean(dpos_part**2)),
             "rest": float(np.mean(rest**2))}
    s = sum(parts.values())
    out["variance_share_pct"] = {k: (100.0 * v / s if s > 0 else 0.0) for k, v in parts.items()}
    out["dominant"] = _dominant(out, parts, reg, regions, external_twin, leg, n, total)
    if scatter_um is not None and out["gap"]["rms_um"] <= 1.25 * scatter_um:
        text = (f"the gap ({out['gap']['rms_um']:.3g} um RMS) is at the repeat scatter after effects "
                f"({scatter_um:.3g} um): nothing systematic stands out")
        if max(parts, key=parts.get) != "rest":
            text += "; what there is, is " + out["dominant"][len("the gap is "):]
        out["dominant"] = text
    return out


def _dominant(out, parts, reg, regions, external_twin, leg, n, total) -> str:
    s = sum(parts.values())
    if s <= 0:
        return "the gap is zero"
    order = sorted(parts, key=lambda k: -parts[k])
    words = []
    op = out.get("outlier_points") or {}
    if op.get("count") and op.get("share_pct", 0) >= 25:
        w = op["worst"][0]
        lead = (f"the gap is dominated by {op['count']} outlier point(s) ({op['share_pct']:.0f} % of its square; "
                f"worst: run {w['run']} at {w['target_mm']:.4g} mm, {w['deviation_um']:+.3g} um off its repeats)")
        return lead + "; besides, it is mostly " + _describe(order[0], out, reg, regions, external_twin, leg)
    for k in order[:2]:
        share = parts[k] / s
        if words and share < 0.25:
            break
        words.append(_describe(k, out, reg, regions, external_twin, leg))
    return "the gap is mostly " + words[0] + ("; also " + words[1] if len(words) > 1 else "")


def _describe(kind, out, reg, regions, external_twin, leg) -> str:
    if kind == "offset":
        return (f"a constant offset ({out['gap']['mean_um']:+.3g} um"
                + ("; an external twin has its own zero)" if external_twin else ")"))
    if kind == "direction":
        return f"a direction-dependent offset (negative minus positive passes {out.get('direction_offset_um', 0):+.3g} um)"
    if kind == "pass":
        text = "a change from pass to pass"
        tr = out.get("pass_trend") or {}
        cond = out["by_condition"]
        if out.get("outlier_passes"):
            runs = ", ".join(str(p["run"]) for p in out["outlier_passes"])
            text += f" (run(s) {runs} far off the others)"
        elif tr and abs(tr.get("r", 0)) >= 0.7:
            if "um_per_h" in tr:
                text += f" that {'grows' if tr['um_per_h'] > 0 else 'falls'} with time ({tr['um_per_h']:+.3g} um/h)"
            else:
                text += f" that {'grows' if tr['um_per_pass'] > 0 else 'falls'} pass after pass ({tr['um_per_pass']:+.3g} um/pass)"
        if cond.get("material_temp") and cond["material_temp"].get("r") is not None and abs(cond["material_temp"]["r"]) >= 0.7:
            text += f", following the material temperature ({cond['material_temp']['um_per_k']:+.3g} um/K)"
        if cond.get("load") and cond["load"].get("r") is not None and abs(cond["load"]["r"]) >= 0.7:
            text += f", following the load ({cond['load']['um_per_kn']:+.3g} um/kN)"
        return text
    if kind == "direction_by_position":
        return "a direction-dependent error that changes along the stroke (the reversal differs from target to target)"
    if kind == "position":
        text = "a function of position"
        rms = [r["rms_um"] for r in out["by_region"]]
        if len(rms) >= 3:
            i = int(np.argmax(rms))
            others = np.delete(np.array(rms), i)
            if rms[i] >= 1.5 * float(np.median(others)):
                text += f", concentrated near {_region_name(i, len(rms))}"
        peaks = out["spectrum"].get("peaks") or []
        if peaks:
            p = peaks[0]
            lead = out["spectrum"].get("lead_mm")
            tag = " (the screw lead)" if lead and abs(p["wavelength_mm"] - lead) <= 0.05 * lead else ""
            if p["amplitude_um"] ** 2 / 2 >= 0.3 * np.mean([r["rms_um"] ** 2 for r in out["by_region"]]):
                text += f", periodic with a {p['wavelength_mm']:.3g} mm wavelength{tag}"
        return text
    return "scatter from point to point that no breakdown explains"
