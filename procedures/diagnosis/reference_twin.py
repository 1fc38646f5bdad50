"""The twin of a reference recording (`station diagnose --twin REF.h5`): its position-only twin
chosen with the reference's own effects taken out, completed with every periodic term the
reference resolves (the screw's lead wobble included), so no effect is named for structure both
recordings share (docs/diagnosis.md "Reference twins").

Apart from procedures/diagnosis/twin.py because it fits the reference's effects with the
selection's LegProblem, which itself builds on the twin's scans: twin <- selection <- here.
"""

from __future__ import annotations

import numpy as np

from drivers.plant.leg import LEAD_MM
from procedures.diagnosis.effects import EFFECTS
from procedures.diagnosis.legdata import LegData, split_legs
from procedures.diagnosis.selection import LegProblem
from procedures.diagnosis.significance import solve_gram
from procedures.diagnosis.twin import (
    MIN_TARGETS_SMOOTH, ExternalTwin, PositionBasis, PositionFit, fit_position_twin, frequency_grid, sinusoid_scan,
)


REFERENCE_ALPHA = 1e-3  # a periodic term of the reference's cell means this significant belongs in its twin
REFERENCE_MAX_ADDED = 12  # periodic terms added beyond the cross-validated twin, per leg
REFERENCE_ROUNDS = 2  # rounds of taking the reference's own effects out before choosing its twin's size
REFERENCE_NUISANCE = ("backlash", "thermal", "load", "drift")  # effects of the reference that are not its position error


def _cell_stats(leg: LegData, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(positions, means, counts) of `r` per target and direction, and the pooled variance of a
    single reading about its cell mean (repeat scatter, pass offsets included: conservative)."""
    cell = leg.target_id * 2 + (leg.direction > 0)
    uc, inv = np.unique(cell, return_inverse=True)
    n = np.bincount(inv).astype(float)
    m = np.bincount(inv, r) / n
    x = np.bincount(inv, leg.x_mm) / n
    dof = leg.n_points - uc.size
    s2 = float(np.sum((r - m[inv]) ** 2)) / dof if dof > 0 else float("nan")
    return x, m, n, s2


def _complete_periodic(leg: LegData, fit: PositionFit, y: np.ndarray, lead_mm: float | None) -> PositionFit:
    """`fit` with every periodic term the recording resolves (issue 35): the screw lead and its
    harmonics below the Nyquist frequency of the spacing (tested at REFERENCE_ALPHA over those),
    then the strongest remaining sinusoid of the scan (look-elsewhere: over the scan's independent
    frequencies), added while significant against the repeat scatter of the cell means. A
    cross-validated twin may leave a small wobble out (the choice of its size is about
    prediction, not about what is resolved); a twin used as a reference must keep it, or the
    structure both recordings share is named as an effect."""
    from scipy.stats import chi2

    if not isinstance(fit.basis, PositionBasis) or leg.n_targets < MIN_TARGETS_SMOOTH:
        return fit
    freqs = list(fit.basis.freqs_per_mm)
    f_nyq = 0.5 / leg.spacing_mm
    grid = frequency_grid(leg)
    lead = [k / lead_mm for k in range(1, 5) if lead_mm and k / lead_mm < 0.9 * f_nyq]
    basis = fit.basis
    for _ in range(REFERENCE_MAX_ADDED):
        r = y - basis.design(leg.x_mm) @ _wls_coef(leg, basis, y)
        x, m, n, s2 = _cell_stats(leg, r)
        if not s2 > 0:
            break
        best = None
        for group, fs, looks in (("lead", [f for f in lead if not _near(f, freqs, leg)], max(len(lead), 1)),
                                 ("scan", [f for f in grid if not _near(f, freqs, leg)], max(1, grid.size // 4))):
            if not fs:
                continue
            amp, a, b = sinusoid_scan(x, m, n, np.asarray(fs), basis.centre_mm)
            k = int(np.argmax(amp))
            ang = 2 * np.pi * fs[k] * (x - basis.centre_mm)
            explained = float(np.sum(n * (a[k] * np.sin(ang) + b[k] * np.cos(ang)) ** 2))
            p = min(1.0, looks * float(chi2.sf(explained / s2, 2)))
            if p < REFERENCE_ALPHA:
                best = fs[k]
                break
        if best is None:
            break
        freqs.append(float(best))
        basis = PositionBasis(basis.centre_mm, basis.half_span_mm, tuple(freqs), basis.trend)
    if basis is fit.basis:
        return fit
    coef = _wls_coef(leg, basis, y)
    return PositionFit(basis, coef, fit.cv_rms_um, (fit.note + "; " if fit.note else "")
                       + f"{len(freqs) - len(fit.basis.freqs_per_mm)} periodic term(s) the reference resolves added",
                       fit.condition_number)


def _near(f: float, freqs: list[float], leg: LegData) -> bool:
    lo, hi = leg.span_mm
    return any(abs(f - g) < 0.5 / max(hi - lo, 1e-9) for g in freqs)  # within half a resolution step


def _wls_coef(leg: LegData, basis: PositionBasis, y: np.ndarray) -> np.ndarray:
    ux, inv = np.unique(leg.x_mm, return_inverse=True)
    w = np.bincount(inv).astype(float)
    m = np.bincount(inv, y) / w
    bw = basis.design(ux) * np.sqrt(w)[:, None]
    return solve_gram(bw.T @ bw, bw.T @ (m * np.sqrt(w)))


def reference_fit(leg: LegData, lead_mm: float | None = LEAD_MM) -> PositionFit:
    """The twin of a leg of a reference recording: its position-only twin chosen with the
    reference's own effects (backlash, thermal, load, drift: fitted jointly, as nuisance) taken out
    of the error, where they would act as noise and keep the twin coarse, then completed with
    every periodic term the reference resolves (`_complete_periodic`)."""
    folds = leg.folds()
    fit = fit_position_twin(leg, folds)
    y = leg.error_um
    nuisance = tuple(EFFECTS[n] for n in REFERENCE_NUISANCE if EFFECTS[n].applicable(leg, False) is None)
    if folds is not None and nuisance and isinstance(fit.basis, PositionBasis):
        for _ in range(REFERENCE_ROUNDS):
            problem = LegProblem(leg, fit.basis.design(leg.x_mm), np.zeros(leg.n_points), folds)
            part = problem.effect_part_um(problem.full_fit(nuisance))
            # only their variation: the twin stays the reference at its mean conditions (its mean
            # temperature's expansion is its position error, as a raw twin always held it)
            _, inv = np.unique(leg.x_mm, return_inverse=True)
            y = leg.error_um - part + (np.bincount(inv, part) / np.bincount(inv))[inv]
            again = fit_position_twin(leg, folds, error_um=y)
            if again.basis == fit.basis:
                break
            fit = again
    return _complete_periodic(leg, fit, y, lead_mm)


def twin_from_recording(points: np.ndarray, source: str = "the reference recording",
                        normalised_points: np.ndarray | None = None, lead_mm: float | None = LEAD_MM) -> ExternalTwin:
    """A fixed twin: the position-only twin fitted on every pass of another recording
    (`reference_fit`: chosen with the reference's own effects taken out, with every periodic
    term the reference resolves, the `lead_mm` wobble included).
    `normalised_points`: the legs of that recording whose error could be normalised to 20 degC
    (their material temperature recorded), with the normalised error: the twin then also carries
    the twin of those (`normalised_twin`), for sessions that carry the material temperature too."""
    fits = {}
    legs = split_legs(points, source)
    for leg, data in legs.items():
        fits[leg] = reference_fit(data, lead_mm)
    return ExternalTwin(
        predict=lambda leg, x, d: fits[leg].predict_um(x),
        kind="reference",
        description=f"position-only twin fitted on {source}",
        legs=frozenset(fits),
        info={str(k): {"columns": v.basis.n_columns,
                       "wavelengths_mm": ([1.0 / f for f in v.basis.freqs_per_mm]
                                          if isinstance(v.basis, PositionBasis) else None),
                       # the mean material temperature of the reference, so a scale found against it can be
                       # tied to the temperature difference (diagnose.py)
                       "material_temp_c": float(np.mean(data.temp_c)) if data.has_temp else None}
              for (k, v), data in zip(fits.items(), legs.values())},
        normalised_twin=(twin_from_recording(normalised_points, f"{source} normalised to 20 degC", lead_mm=lead_mm)
                         if normalised_points is not None and len(normalised_points) else None),
    )
