"""Variants of named effects: the same physics changing with conditions or position (issue 25).

A variant is its effect's columns plus a few more; it replaces the effect only when the extra
columns are significant (Wald test on them alone, against the scatter between passes) and add
more than the threshold on held-out passes. The finding keeps the effect's name and says which
variant (`variant`), with the variant's parameters:

- backlash / temperature: `reversal_um` at 20 C and `reversal_um_per_k` (the nut preload changes
  as the leg warms). Extra column -direction/2 * dT.
- backlash / position: the reversal as a parabola along the stroke (nut wear over the most-used
  part): `reversal_max_um` at `reversal_max_at_mm`, `reversal_min_um` at `reversal_min_at_mm`,
  `reversal_change_um` = max - min over the measured stroke. Extra columns -direction/2 * u,
  -direction/2 * u^2, u = position scaled to -1..1 over the stroke.
- backlash / wind-up: lost motion that winds up over `windup_mm` after each reversal: the error
  starts at the old direction's value and approaches the new one as exp(-s / windup_mm), s =
  travel since the pass's first target (the travel before it, the overrun, only scales the
  amplitude). Extra column direction * exp(-s / windup_mm), windup_mm found by a scan on the
  training passes.
- thermal / gradient: expansion growing along the screw (the nut end warmer): the error grows
  with the square of position as the leg warms. Extra column dT * (x/1000)^2;
  `expansion_gradient_ppm_per_k_per_m` = 2 x its coefficient (the change of the local expansion
  per K per metre along the screw), `expansion_ppm_per_k` the slope at mid-stroke.
- stacked variants (issue 35): two variants of one effect at once, e.g. backlash /
  temperature+position (a reversal growing with temperature on a nut worn over a stretch): the
  effect's columns, then each part's extra columns; the parameters of both parts. Each part must
  earn its place over the other part alone (selection.py).

A wind-up shorter than the target spacing is not resolvable (`BacklashWindup.unresolvable`): only
the first target of each pass sees it, so it cannot be told from an offset of that target.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from procedures.diagnosis.effects import EFFECTS, TEMP_REF_C, Effect, _se
from procedures.diagnosis.legdata import LegData

MIN_TEMP_RANGE_VARIANT_K = 0.2  # a reversal or slope per kelvin needs a real temperature change
WINDUP_GRID_MM = np.geomspace(0.3, 40.0, 48)  # refined by a parabola in log length


class Variant(Effect):
    """`base`'s columns plus `n_extra` more (the last ones)."""

    def __init__(self, base: Effect, variant: str, n_extra: int):
        super().__init__(f"{base.name}:{variant}", base.n_params + n_extra)
        object.__setattr__(self, "base", base)
        object.__setattr__(self, "variant", variant)
        object.__setattr__(self, "n_extra", n_extra)

    def applicable(self, leg, external_twin):
        return self.base.applicable(leg, external_twin)

    def extra(self, leg: LegData, spec=None) -> np.ndarray:
        raise NotImplementedError

    def columns(self, leg, spec=None):
        return np.column_stack([self.base.columns(leg), self.extra(leg, spec)])

    def __hash__(self):
        return hash(self.name)


def _dt(leg: LegData) -> np.ndarray:
    return leg.temp_c - TEMP_REF_C


class BacklashTemperature(Variant):
    def applicable(self, leg, external_twin):
        why = super().applicable(leg, external_twin)
        if why is None and not (leg.has_temp and np.ptp(leg.temp_c) >= MIN_TEMP_RANGE_VARIANT_K):
            why = "needs the material temperature to change by 0.2 K"
        return why

    def extra(self, leg, spec=None):
        return (-0.5 * leg.direction * _dt(leg))[:, None]

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        p = {"reversal_um": float(coef[0]), "reversal_um_per_k": float(coef[1])}
        se = {"reversal_um": _se(cov, 0), "reversal_um_per_k": _se(cov, 1)}
        if leg is not None:
            t = float(np.mean(leg.temp_c))
            p["reversal_at_mean_temp_um"] = float(coef[0] + coef[1] * (t - TEMP_REF_C))
            p["mean_temp_c"] = t
        return p, se


def _u(leg: LegData, x=None) -> np.ndarray:
    lo, hi = leg.span_mm
    x = leg.x_mm if x is None else x
    return (x - 0.5 * (lo + hi)) / max(0.5 * (hi - lo), 1e-9)


class BacklashPosition(Variant):
    def applicable(self, leg, external_twin):
        why = super().applicable(leg, external_twin)
        if why is None and leg.n_targets < 5:
            why = f"only {leg.n_targets} targets: a reversal that changes along the stroke needs at least 5"
        return why

    def extra(self, leg, spec=None):
        u = _u(leg)
        return np.column_stack([-0.5 * leg.direction * u, -0.5 * leg.direction * u * u])

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        c0, c1, c2 = (float(v) for v in coef[:3])
        p = {"reversal_um": c0}
        se = {"reversal_um": _se(cov, 0)}
        if leg is not None:
            lo, hi = leg.span_mm
            x = np.linspace(lo, hi, 361)
            u = _u(leg, x)
            r = c0 + c1 * u + c2 * u * u
            i, j = int(np.argmax(r)), int(np.argmin(r))
            p.update({"reversal_max_um": float(r[i]), "reversal_max_at_mm": float(x[i]),
                      "reversal_min_um": float(r[j]), "reversal_min_at_mm": float(x[j]),
                      "reversal_change_um": float(r[i] - r[j])})
            # standard error of the change, linearised at the two ends found
            g = np.array([0.0, u[i] - u[j], u[i] ** 2 - u[j] ** 2])
            se["reversal_change_um"] = float(np.sqrt(max(g @ cov[:3, :3] @ g, 0.0)))
        return p, se


def since_first_target_mm(leg: LegData) -> np.ndarray:
    """Travel since the first point of each pass, mm (the wind-up's clock, up to the overrun)."""
    first = np.full(leg.n_passes, np.nan)
    order = np.arange(leg.n_points)[::-1]
    first[leg.pass_id[order]] = leg.x_mm[order]  # the last write per pass is its first point
    return np.abs(leg.x_mm - first[leg.pass_id])


class BacklashWindup(Variant):
    searched = True

    def unresolvable(self, leg: LegData, spec) -> str | None:
        """Why a wind-up of `spec` mm cannot be named on this leg (None when it can): shorter than
        the target spacing, only the first target of each pass would see it."""
        if spec is not None and spec < leg.spacing_mm:
            return (f"a wind-up of {spec:.3g} mm is shorter than the {leg.spacing_mm:.3g} mm target spacing: only the "
                    "first target of each pass sees it, so it cannot be told from an offset of that target")
        return None

    def extra(self, leg, spec=None):
        return (leg.direction * np.exp(-since_first_target_mm(leg) / spec))[:, None]

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        return ({"reversal_um": float(coef[0]), "windup_mm": float(spec), "windup_start_um": float(coef[1])},
                {"reversal_um": _se(cov, 0), "windup_start_um": _se(cov, 1)})

    def search(self, leg: LegData, y: np.ndarray, rows: np.ndarray) -> float:
        """The wind-up length (mm) that best explains the training rows' direction-dependent
        shape: target means and a line per pass taken out of both data and column (so neither the
        twin, a reversal, pass offsets nor slopes can bias it); parabolic refinement in log L."""
        n_rows = rows.size
        tid, pid, x = leg.target_id[rows], leg.pass_id[rows], leg.x_mm[rows]
        # target means and a least-squares line per pass, for all grid columns at once
        t_one = sparse.csr_matrix((np.ones(n_rows), (tid, np.arange(n_rows))), shape=(leg.n_targets, n_rows))
        t_cnt = np.maximum(np.asarray(t_one.sum(1)).ravel(), 1.0)
        p_one = sparse.csr_matrix((np.ones(n_rows), (pid, np.arange(n_rows))), shape=(leg.n_passes, n_rows))
        n = np.asarray(p_one.sum(1)).ravel()
        sx, sxx = p_one @ x, p_one @ (x * x)
        den = np.where(np.abs(n * sxx - sx**2) > 1e-12, n * sxx - sx**2, 1.0)

        def clean(v):
            v = v - (t_one @ v / t_cnt[:, None])[tid]
            sv, sxv = p_one @ v, p_one @ (x[:, None] * v)
            slope = (n[:, None] * sxv - sx[:, None] * sv) / den[:, None]
            icpt = np.divide(sv - slope * sx[:, None], n[:, None], out=np.zeros_like(sv), where=n[:, None] > 0)
            return v - icpt[pid] - slope[pid] * x[:, None]

        yr = clean(y[rows][:, None])[:, 0]
        s = since_first_target_mm(leg)[rows]
        c = clean(leg.direction[rows, None] * np.exp(-s[:, None] / WINDUP_GRID_MM[None, :]))
        cc = np.einsum("ij,ij->j", c, c)
        gain = np.where(cc > 1e-12, (yr @ c) ** 2 / np.maximum(cc, 1e-300), 0.0)
        k = int(np.argmax(gain))
        lg = np.log(WINDUP_GRID_MM)
        if 0 < k < gain.size - 1:
            a, b, c = gain[k - 1], gain[k], gain[k + 1]
            den = a - 2 * b + c
            off = 0.5 * (a - c) / den if den < 0 else 0.0
            return float(np.exp(lg[k] + np.clip(off, -0.5, 0.5) * (lg[1] - lg[0])))
        return float(WINDUP_GRID_MM[k])


class ThermalGradient(Variant):
    def applicable(self, leg, external_twin):
        why = super().applicable(leg, external_twin)
        if why is None and np.ptp(leg.temp_c) < MIN_TEMP_RANGE_VARIANT_K:
            why = "needs the material temperature to change by 0.2 K"
        return why

    def extra(self, leg, spec=None):
        return (_dt(leg) * (leg.x_mm / 1000.0) ** 2)[:, None]

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        p, se = self.base.parameters(coef[:2], cov[:2, :2], spec, leg, resid_um)
        p["expansion_gradient_ppm_per_k_per_m"] = 2.0 * float(coef[2])
        se["expansion_gradient_ppm_per_k_per_m"] = 2.0 * _se(cov, 2)
        return p, se


class Stacked(Variant):
    """Two variants of one effect at once: the effect's columns, then each part's extra columns
    (`parts`, in that order). Searched (the wind-up length) when a part is: the search is the
    part's and shares its cache (`search_key`)."""

    def __init__(self, *parts: Variant):
        base = parts[0].base
        # n_extra: the extra columns (their Wald test); n_params counts the wind-up's length too
        super().__init__(base, "+".join(p.variant for p in parts), sum(_extra_columns(p) for p in parts))
        object.__setattr__(self, "n_params", base.n_params + sum(p.n_extra for p in parts))
        object.__setattr__(self, "parts", parts)
        searched = [p for p in parts if getattr(p, "searched", False)]
        object.__setattr__(self, "searched", bool(searched))
        if searched:
            object.__setattr__(self, "search_key", searched[0].name)
            object.__setattr__(self, "search", searched[0].search)

    def applicable(self, leg, external_twin):
        for p in self.parts:
            why = p.applicable(leg, external_twin)
            if why is not None:
                return why
        return None

    def unresolvable(self, leg, spec):
        for p in self.parts:
            why = getattr(p, "unresolvable", None)
            if why is not None and why(leg, spec) is not None:
                return why(leg, spec)
        return None

    def extra(self, leg, spec=None):
        return np.column_stack([p.extra(leg, spec if getattr(p, "searched", False) else None) for p in self.parts])

    def part_slices(self) -> dict[str, slice]:
        """Each part's extra columns within this variant's columns (the effect's own come first)."""
        out, k = {}, _base_columns(self.base)
        for p in self.parts:
            out[p.variant] = slice(k, k + _extra_columns(p))
            k += _extra_columns(p)
        return out

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        nb = _base_columns(self.base)
        params, se = {}, {}
        for p, sl in zip(self.parts, self.part_slices().values()):
            idx = list(range(nb)) + list(range(sl.start, sl.stop))
            pp, ps = p.parameters(coef[idx], cov[np.ix_(idx, idx)], spec if getattr(p, "searched", False) else None,
                                  leg, resid_um)
            for k, v in pp.items():
                params.setdefault(k, v)
            for k, v in ps.items():
                se.setdefault(k, v)
        return params, se


def _extra_columns(v: Variant) -> int:
    return 1 if getattr(v, "searched", False) else v.n_extra  # the wind-up: one column, its length a parameter


def _base_columns(effect: Effect) -> int:
    """How many columns the plain effect has (its parameters' columns, not its free parameters)."""
    return {"thermal": 2, "load": 2, "speed": 2, "cyclic": 2}.get(effect.name, 1)


_TEMPERATURE = BacklashTemperature(EFFECTS["backlash"], "temperature", 1)
_POSITION = BacklashPosition(EFFECTS["backlash"], "position", 2)
_WINDUP = BacklashWindup(EFFECTS["backlash"], "windup", 2)

VARIANTS: dict[str, tuple[Variant, ...]] = {
    "backlash": (_TEMPERATURE, _POSITION, _WINDUP, Stacked(_TEMPERATURE, _POSITION), Stacked(_TEMPERATURE, _WINDUP)),
    "thermal": (ThermalGradient(EFFECTS["thermal"], "gradient", 1),),
}
"""Variants tried for each named effect (the wind-up counts its length as a parameter)."""
