"""`fit(points, method=...)`: per-leg models from a session's points, with honest statistics."""

from __future__ import annotations

from typing import Any, Iterable

import numpy as np

from procedures.vocabulary import InputError
from procedures.fit.bidirectional import MAX_FOURIER_TERMS, fit_bidirectional_leg
from procedures.fit.crossval import cycle_folds, heldout_residuals_um
from procedures.fit.dynamic import is_onthefly, static_points
from procedures.fit.data import LegData, split_legs
from procedures.fit.figures import range_um, rms_um
from procedures.fit.model import METHODS, FitStats, LegErrorModel, LegFit
from procedures.fit.noise import estimate_noise_floor
from procedures.fit.paper import DEFAULT_N_PARAMS, fit_paper_leg
from procedures.fit.reversal_probes import apply_probes, is_probe

_DEFAULT_OPTS = ("lead_mm", "trend_degree", "reversal_degree", "fourier_terms", "lead_harmonics",
                 "max_fourier_terms", "nested")


def _stats(data: LegData, folds: np.ndarray | None, heldout: np.ndarray | None, note: str = "") -> FitStats:
    noise = estimate_noise_floor(data)
    if heldout is None:
        note = note or "held-out figures need at least two cycles"
    return FitStats(
        n_points=data.n_points,
        n_passes=data.n_passes,
        n_cycles=data.n_cycles,
        dropped=data.dropped,
        folds=0 if folds is None else int(folds.max()) + 1,
        noise_floor_um=noise.noise_floor_um,
        within_pass_um=noise.within_pass_um,
        heldout_rms_um=None if heldout is None else rms_um(heldout),
        range_before_um=range_um(data.error_um),
        heldout_range_um=None if heldout is None else range_um(heldout),
        note=note,
    )


def fit_leg(data: LegData, method: str = "default", **opts: Any) -> LegFit:
    """Fit one leg's `LegData` (see `fit` for the options)."""
    folds = cycle_folds(data)
    where = f"leg {data.leg}"
    if method == "paper":
        n_params = int(opts.get("n_params", DEFAULT_N_PARAMS))
        leg_fit = fit_paper_leg(data, n_params, where=where)
        heldout = None
        if folds is not None:
            try:
                heldout = heldout_residuals_um(data, folds, lambda d: fit_paper_leg(d, n_params, where=where))
            except InputError as exc:
                leg_fit.stats = _stats(data, None, None, f"no held-out figures: {exc}")
                return leg_fit
        leg_fit.stats = _stats(data, folds, heldout)
        return leg_fit
    if method == "default":
        kw = {k: opts[k] for k in _DEFAULT_OPTS if k in opts and (opts[k] is not None or k == "lead_mm")}
        leg_fit, heldout, info = fit_bidirectional_leg(data, folds, where=where, **kw)
        leg_fit.stats = _stats(data, folds, heldout)
        return leg_fit
    raise InputError(f"unknown fit method {method!r}; use one of {', '.join(METHODS)}")


def fit(
    points: np.ndarray,
    method: str = "default",
    *,
    legs: Iterable[int] | None = None,
    source: dict[str, str] | None = None,
    n_params: int = DEFAULT_N_PARAMS,
    lead_mm: float | str | None = "auto",
    trend_degree: int | None = None,
    reversal_degree: int | None = None,
    fourier_terms: int | None = None,
    lead_harmonics: int | None = None,
    max_fourier_terms: int = MAX_FOURIER_TERMS,
    nested: bool = True,
) -> LegErrorModel:
    """Fit a leg-error model to a session's points (POINT_DTYPE array).

    method "default": the bidirectional model (procedures.fit.bidirectional); sizes left None
    are chosen by cross-validation over held-out cycles; `lead_mm` is the screw lead (mm) for the
    lead harmonics, "auto" (default) to look for a significant short period in the data,
    None for no lead harmonics. method "paper": the seed paper's Algorithm 1 with `n_params` cosine terms
    (needs uniformly spaced targets). `legs` restricts the fit to some legs. `source` =
    {"path", "sha256"} of the recording, stored in the model.

    Errors are measured minus commanded (um); positions mm. Raises `InputError` for data a
    method cannot use, naming the leg and what to do.
    """
    if method not in METHODS:
        raise InputError(f"unknown fit method {method!r}; use one of {', '.join(METHODS)}")
    if isinstance(lead_mm, str):
        if lead_mm != "auto":
            raise InputError(f"screw lead must be a number of mm, 'auto' or none, got {lead_mm!r}")
    elif lead_mm is not None and not (np.isfinite(lead_mm) and lead_mm > 0):
        raise InputError(f"screw lead must be a positive number of mm, got {lead_mm}")
    src = (source or {}).get("path", "") or "the session"
    probes = points[is_probe(points)] if len(points) else points
    if is_onthefly(points):  # on-the-fly readings: fit their static part (docs/onthefly.md); probes dropped
        points = static_points(points, src)
    by_leg = split_legs(points, source=src)
    if legs is not None:
        wanted = sorted(set(int(x) for x in legs))
        missing = [x for x in wanted if x not in by_leg]
        if missing:
            raise InputError(f"{src}: no points for leg(s) {missing}; the recording has legs {sorted(by_leg)}")
        by_leg = {k: by_leg[k] for k in wanted}
    if method == "paper":
        opts: dict[str, Any] = {"n_params": int(n_params)}
    else:
        opts = {"lead_mm": lead_mm, "trend_degree": trend_degree, "reversal_degree": reversal_degree,
                "fourier_terms": fourier_terms, "lead_harmonics": lead_harmonics,
                "max_fourier_terms": int(max_fourier_terms), "nested": bool(nested)}
    fits = {leg: fit_leg(data, method, **opts) for leg, data in by_leg.items()}
    if method == "default" and len(probes):  # the reversal from the probes (procedures/fit/reversal_probes.py)
        for leg, leg_fit in fits.items():
            apply_probes(leg_fit, probes[probes["leg"] == leg])
    return LegErrorModel(method, fits, source=source, options=opts)
