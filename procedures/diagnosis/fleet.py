"""The fleet twin: the legs of one type as the twin of one of them (`--twin fleet:TYPE`).

Each sibling leg gives an error map: its mean error per target and direction (measured minus
commanded, um; direction +1 = approached while the position increases), interpolated onto the
targets of the leg under diagnosis, with its own mean taken out (every session has its own
zero). The twin is the mean map per direction; its spread the per-target standard deviation
across the siblings. The comparison reduces each map to a few features and says how many
sigma (standard deviations of the siblings' values) this leg's value lies from their mean:

- reversal (negative minus positive direction, as `reversal_um`) over the stroke, and its
  excess over that mean in each fifth of the stroke (a larger reversal at an end, ...);
- scale: slope of the direction mean, ppm (um per m);
- cyclic at the lead: amplitude of a sinusoid at the screw lead in the detrended direction mean;
- shape: the detrended direction mean averaged over each fifth of the stroke (a local bump).

Fifths rather than single targets: a sibling set is small (3 to a few dozen legs), so a feature
per target would find 3 sigma somewhere on a clean leg just by the number of targets looked at.
For the same reason a feature stands out only when, besides lying more than 3 sigma off, it
would be that far off a sibling set this small with less than the two-sided 3-sigma chance
(0.27 %) among all features looked at: the t prediction interval of n siblings (n - 1 degrees
of freedom, sd x sqrt(1 + 1/n)), Bonferroni over the features (`p_value_all_features`).

Which maps (raw or normalised to 20 degC) is the caller's choice (station/services/twins.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import t as t_dist

from procedures.diagnosis.twin import ExternalTwin, sinusoid_scan

MIN_SIBLINGS = 3
STANDS_OUT_SIGMA = 3.0
FAMILY_P = 0.0027  # the two-sided chance of a normal value beyond 3 sigma
REGIONS = 5


@dataclass(frozen=True)
class ErrorMap:
    """Mean error per target and direction of one leg of one session (NaN where a direction has
    no reading at a target)."""

    targets_mm: np.ndarray
    up_um: np.ndarray
    down_um: np.ndarray

    def at(self, x_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(up, down) interpolated at `x_mm` (held beyond the end targets), their common mean
        over `x_mm` taken out."""
        up, down = (_interp(x_mm, self.targets_mm, v) for v in (self.up_um, self.down_um))
        zero = 0.5 * (np.mean(up) + np.mean(down))
        return up - zero, down - zero


def _interp(x, xp, fp):
    ok = np.isfinite(fp)
    if not ok.any():
        return np.full(np.shape(x), np.nan)
    return np.interp(x, xp[ok], fp[ok])


def error_map(points: np.ndarray, leg: int) -> ErrorMap:
    """The error map of leg `leg` in a POINT_DTYPE array (its `error_um`, raw or normalised)."""
    p = points[(points["leg"] == leg) & np.isfinite(points["error_um"])]
    x = np.round(np.asarray(p["target_mm"], dtype=float), 3)  # targets repeat exactly; a micrometre apart are one
    ux, inv = np.unique(x, return_inverse=True)
    out = []
    for d in (1, -1):
        m = p["direction"] == d
        n = np.bincount(inv[m], minlength=ux.size)
        s = np.bincount(inv[m], p["error_um"][m], minlength=ux.size)
        out.append(np.divide(s, n, out=np.full(ux.size, np.nan), where=n > 0))
    return ErrorMap(ux, out[0], out[1])


def _regions(x: np.ndarray) -> list[tuple[float, float, np.ndarray]]:
    lo, hi = float(x.min()), float(x.max())
    edges = np.linspace(lo, hi, REGIONS + 1)
    out = []
    for i in range(REGIONS):
        m = (x >= edges[i]) & ((x < edges[i + 1]) if i < REGIONS - 1 else (x <= edges[i + 1]))
        if m.any():
            out.append((float(edges[i]), float(edges[i + 1]), m))
    return out


def features(x_mm: np.ndarray, up: np.ndarray, down: np.ndarray, lead_mm: float | None) -> dict[str, dict]:
    """Feature name -> {"value", "unit", "from_mm", "to_mm", "words"} of one map on `x_mm`."""
    mid, rev = 0.5 * (up + down), down - up
    out: dict[str, dict] = {"reversal": {"value": float(np.mean(rev)), "unit": "um",
                                         "words": "the reversal (mean over the stroke)"}}
    for a, b, m in _regions(x_mm):
        out[f"reversal {a:.0f}..{b:.0f} mm"] = {"value": float(np.mean(rev[m]) - np.mean(rev)), "unit": "um",
                                                "from_mm": a, "to_mm": b,
                                                "words": f"the reversal between {a:.0f} and {b:.0f} mm (beyond the "
                                                         "leg's mean reversal)"}
    half = max(0.5 * float(np.ptp(x_mm)), 1e-9)
    centre = 0.5 * float(x_mm.min() + x_mm.max())
    u = (x_mm - centre) / half
    slope, icpt = np.polyfit(u, mid, 1)
    out["scale"] = {"value": float(slope / half * 1000.0), "unit": "ppm", "words": "the scale (slope of the error)"}
    detrended = mid - (slope * u + icpt)
    spacing = float(np.median(np.diff(np.unique(x_mm)))) if x_mm.size > 1 else np.inf
    if lead_mm and lead_mm > 2 * spacing:
        amp = sinusoid_scan(x_mm, detrended, np.ones_like(x_mm), np.array([1.0 / lead_mm]), centre)[0]
        out["cyclic at the lead"] = {"value": float(amp[0]), "unit": "um",
                                     "words": f"the cyclic error at the {lead_mm:g} mm lead (amplitude)"}
    for a, b, m in _regions(x_mm):
        out[f"shape {a:.0f}..{b:.0f} mm"] = {"value": float(np.mean(detrended[m])), "unit": "um", "from_mm": a,
                                             "to_mm": b, "words": f"the error between {a:.0f} and {b:.0f} mm (a local "
                                             "bump or dip against the straight line)"}
    return out


def content_key(m: ErrorMap) -> bytes:
    """A sibling's measurement by content: its error map (targets, mean error per direction) to
    1 nm; two files holding the same readings under different names give the same key."""
    return b"".join(np.round(np.nan_to_num(np.asarray(v, float), nan=1e9), 3).tobytes()
                    for v in (m.targets_mm, m.up_um, m.down_um))


def independent_maps(maps: dict[str, ErrorMap]) -> tuple[dict[str, ErrorMap], dict[str, str]]:
    """(the maps with each measurement once, serial -> the serial whose map it repeats exactly):
    copies of one session under several names would shrink the siblings' spread and put a leg
    hundreds of sigma off (issue 35); the first serial in sorted order is kept."""
    first: dict[bytes, str] = {}
    dup: dict[str, str] = {}
    for serial in sorted(maps):
        key = content_key(maps[serial])
        if key in first:
            dup[serial] = first[key]
        else:
            first[key] = serial
    return {k: v for k, v in maps.items() if k not in dup}, dup


@dataclass
class FleetLeg:
    """The siblings of one leg under diagnosis: their serials and maps on this leg's targets."""

    x_mm: np.ndarray
    serials: list[str]
    up: np.ndarray  # siblings x targets
    down: np.ndarray

    @property
    def n(self) -> int:
        return len(self.serials)

    def mean(self) -> tuple[np.ndarray, np.ndarray]:
        return self.up.mean(0), self.down.mean(0)

    def spread(self) -> tuple[np.ndarray, np.ndarray]:
        return self.up.std(0, ddof=1), self.down.std(0, ddof=1)


def fleet_leg(x_mm: np.ndarray, siblings: dict[str, ErrorMap]) -> FleetLeg:
    x = np.unique(np.round(np.asarray(x_mm, dtype=float), 3))
    maps = [siblings[s].at(x) for s in siblings]
    return FleetLeg(x, list(siblings), np.array([m[0] for m in maps]), np.array([m[1] for m in maps]))


def compare(fl: FleetLeg, this: ErrorMap, leg_type: str, lead_mm: float | None) -> dict:
    """How far each feature of `this` leg lies from its siblings, in sigma (sibling standard
    deviation, ddof 1), the largest first; `finding` names the largest when it is above
    STANDS_OUT_SIGMA, else says none stands out."""
    up, down = this.at(fl.x_mm)
    mine = features(fl.x_mm, up, down, lead_mm)
    sib = [features(fl.x_mm, fl.up[i], fl.down[i], lead_mm) for i in range(fl.n)]
    rows = []
    for name, f in mine.items():
        vals = np.array([s[name]["value"] for s in sib])
        mean, sd = float(vals.mean()), float(vals.std(ddof=1))
        sigma = (f["value"] - mean) / sd if sd > 0 else None
        p = (min(1.0, len(mine) * 2 * float(t_dist.sf(abs(sigma) / np.sqrt(1 + 1 / fl.n), fl.n - 1)))
             if sigma is not None else None)
        rows.append({"feature": name, **{k: v for k, v in f.items() if k != "words"}, "words": f["words"],
                     "fleet_mean": mean, "fleet_sd": sd, "sigma": sigma, "p_value_all_features": p,
                     "stands_out": sigma is not None and abs(sigma) > STANDS_OUT_SIGMA and p < FAMILY_P})
    rows.sort(key=lambda r: -abs(r["sigma"] or 0.0))
    mu, md = fl.mean()
    su, sd_ = fl.spread()
    out = {"leg_type": leg_type, "siblings": fl.n, "sibling_serials": fl.serials, "features": rows,
           "map": {"position_mm": fl.x_mm.tolist(), "fleet_up_um": mu.tolist(), "fleet_down_um": md.tolist(),
                   "fleet_up_sd_um": su.tolist(), "fleet_down_sd_um": sd_.tolist(),
                   "leg_up_um": up.tolist(), "leg_down_um": down.tolist()}}
    top = rows[0] if rows else None
    if top is not None and top["stands_out"]:
        more = "larger" if top["sigma"] > 0 else "smaller"
        out["finding"] = {
            "feature": top["feature"], "sigma": top["sigma"], "value": top["value"], "unit": top["unit"],
            "note": (f"{top['words']} of this leg, {top['value']:+.3g} {top['unit']}, lies {abs(top['sigma']):.1f} sigma "
                     f"{'above' if top['sigma'] > 0 else 'below'} its {fl.n} sibling legs of type {leg_type} "
                     f"(their mean {top['fleet_mean']:+.3g}, sd {top['fleet_sd']:.3g} {top['unit']}): {more} than the "
                     f"fleet's (p = {top['p_value_all_features']:.2g} for any of {len(rows)} features this far off "
                     f"{fl.n} siblings)")}
        others = [r["feature"] for r in rows[1:] if r["stands_out"]]
        if others:
            out["finding"]["also_above_3_sigma"] = others
    else:
        s = f"{abs(top['sigma']):.1f} sigma ({top['feature']})" if top and top["sigma"] is not None else "n/a"
        out["finding"] = None
        out["finding_note"] = (f"no feature of this leg stands out from its {fl.n} sibling legs of type {leg_type} "
                               f"(largest: {s}; standing out takes more than {STANDS_OUT_SIGMA:g} sigma and p < "
                               f"{FAMILY_P:g} over all {len(rows)} features)")
    return out


@dataclass
class FleetTwin(ExternalTwin):
    """The siblings' mean map per direction as a twin (`predict_um` follows the direction: the
    fleet's reversal is part of the twin, so the gap is this leg against its siblings)."""

    fleet: dict[int, FleetLeg] = field(default_factory=dict)
    leg_type: str = ""
    normalised: bool = False
    comparisons: dict[int, dict] = field(default_factory=dict)  # leg -> `comparison`, once made

    def comparison(self, leg: int, this: ErrorMap, lead_mm: float | None) -> dict:
        out = compare(self.fleet[leg], this, self.leg_type, lead_mm)
        out["basis"] = "normalised to 20 degC" if self.normalised else "raw"
        if self.info.get("duplicates"):
            out["duplicates_counted_once"] = dict(self.info["duplicates"])
        self.comparisons[leg] = out
        return out

    def effect_guard(self, leg: int, effect: str) -> str | None:
        """Why `effect` is not tried against this fleet on `leg` (None: it is): a scale is named
        only when the feature comparison supports it (this leg's scale stands out from its
        siblings'); else the siblings' own spread of slopes is all the diagnosis would see
        (issue 35: 120 and 463 ppm named on real data where no feature stood out)."""
        if effect != "scale" or leg not in self.comparisons:
            return None
        row = next((r for r in self.comparisons[leg]["features"] if r["feature"] == "scale"), None)
        if row is not None and row["stands_out"]:
            return None
        sigma = f"{row['sigma']:+.1f} sigma" if row and row.get("sigma") is not None else "no spread to compare"
        return (f"the scale of this leg does not stand out from its {self.fleet[leg].n} siblings' ({sigma}): against a "
                "fleet a slope is named only when the feature comparison supports it")


def fleet_twin(fleet: dict[int, FleetLeg], leg_type: str, description: str, normalised: bool,
               info: dict | None = None) -> FleetTwin:
    means = {leg: fl.mean() for leg, fl in fleet.items()}

    def predict(leg, x, d):
        fl = fleet[leg]
        up, down = means[leg]
        return np.where(np.asarray(d) < 0, np.interp(x, fl.x_mm, down), np.interp(x, fl.x_mm, up))

    return FleetTwin(predict=predict, kind="fleet", description=description, legs=frozenset(fleet),
                     info=info or {}, fleet=fleet, leg_type=leg_type, normalised=normalised)
