"""The digital twin the gap is measured against.

Without an external twin, the twin is a smooth function of position per leg (no direction,
time, temperature or load terms) fitted on the same recording: a trend plus the strongest
sinusoids of position (frequencies k / (2 x span), ranked by amplitude as in the seed paper, but
fitted by least squares at the real positions, so irregular spacing is fine and a trend does not
ring), their number chosen by cross-validation over held-out cycles.

An external twin is anything with `predict_um(leg, x_mm, direction) -> error_um` (measured minus
commanded, um): a saved leg-error model, a twin fitted on a reference recording, or the plant's own
systematic error (`plant_twin`: the leg's physics of drivers/plant, which the simulated devices run on).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.linalg import solve_triangular

from drivers.plant.leg import PlantConfig, systematic_error_um
from procedures.diagnosis.legdata import LegData
from procedures.diagnosis.significance import condition_number, solve_gram
from procedures.vocabulary import InputError

MAX_SINUSOIDS = 40  # per leg; the paper keeps up to 100 numbers = 33 amplitude/frequency/phase triples
CV_TOLERANCE = 0.005  # take the smallest twin whose held-out MSE is within 0.5 % of the best
MIN_TARGETS_SMOOTH = 8  # below this a smooth twin cannot be told from the target means
NESTED_RTOL = 1e-6  # a sinusoid less than this share independent of the ones before it ends the twin: more would
# make the twin (and every fold fit of it with effects) ill-conditioned, its coefficients large and cancelling


@dataclass(frozen=True)
class PositionBasis:
    """Columns of a position-only twin: 1, (x - centre)/half_span, then sin/cos(2 pi f (x - centre))
    for each frequency f (cycles per mm). `trend` False drops the linear column (one target)."""

    centre_mm: float
    half_span_mm: float
    freqs_per_mm: tuple[float, ...] = ()
    trend: bool = True

    @property
    def n_columns(self) -> int:
        return 1 + int(self.trend) + 2 * len(self.freqs_per_mm)

    def design(self, x_mm) -> np.ndarray:
        x = np.asarray(x_mm, dtype=float) - self.centre_mm
        cols = [np.ones_like(x)]
        if self.trend:
            cols.append(x / self.half_span_mm)
        for f in self.freqs_per_mm:
            a = 2 * np.pi * f * x
            cols.append(np.sin(a))
            cols.append(np.cos(a))
        return np.column_stack(cols)


@dataclass(frozen=True)
class TargetBasis:
    """Columns of a per-target twin for legs with few targets: tent (hat) functions at the
    targets, i.e. linear interpolation between target means, constant beyond the end targets."""

    knots_mm: tuple[float, ...]

    @property
    def n_columns(self) -> int:
        return len(self.knots_mm)

    def design(self, x_mm) -> np.ndarray:
        x = np.asarray(x_mm, dtype=float)
        k = np.asarray(self.knots_mm)
        if k.size == 1:
            return np.ones((x.size, 1))
        eye = np.eye(k.size)
        return np.column_stack([np.interp(x, k, eye[j]) for j in range(k.size)])


@dataclass(frozen=True)
class PositionFit:
    """A fitted position-only twin of one leg: `predict_um(x_mm)` = design(x) @ coef."""

    basis: PositionBasis | TargetBasis
    coef: np.ndarray
    cv_rms_um: float | None  # held-out RMS of measured minus twin (all terms of the gap), um
    note: str = ""
    condition_number: float | None = None  # of the weighted design at the targets (columns scaled to unit norm)

    def predict_um(self, x_mm) -> np.ndarray:
        return self.basis.design(x_mm) @ self.coef


def frequency_grid(leg: LegData) -> np.ndarray:
    """Candidate frequencies (cycles/mm): k / (2 span) up to the Nyquist frequency of the
    usual target spacing."""
    lo, hi = leg.span_mm
    span = hi - lo
    if leg.n_targets < 3 or span <= 0:
        return np.zeros(0)
    f_nyq = 0.5 / leg.spacing_mm
    k_max = int(min(np.floor(f_nyq * 2 * span), 800))
    return np.arange(1, k_max + 1) / (2 * span)


def _amplitudes(ss, cc, sc, ys, yc, wsum: float):
    det = ss * cc - sc * sc
    # near the Nyquist frequency of a regular grid sin (or cos) vanishes at every target: such a
    # frequency cannot be resolved, its amplitude is reported as 0
    bad = (det < 1e-3 * ss * cc) | (ss < 1e-6 * wsum) | (cc < 1e-6 * wsum)
    det = np.where(bad, np.inf, det)
    a = (cc * ys - sc * yc) / det
    b = (ss * yc - sc * ys) / det
    return np.hypot(a, b), a, b


def sinusoid_scan(x_mm: np.ndarray, y_um: np.ndarray, w: np.ndarray, freqs: np.ndarray, centre_mm: float = 0.0):
    """Weighted least-squares sinusoid amplitude of `y_um` at each frequency (a Lomb-Scargle
    style scan for irregular positions). Returns (amplitude_um, a_sin, b_cos) per frequency."""
    if freqs.size == 0:
        z = np.zeros(0)
        return z, z, z
    ang = 2 * np.pi * np.outer(x_mm - centre_mm, freqs)
    s, c = np.sin(ang), np.cos(ang)
    wy = w * y_um
    return _amplitudes(w @ (s * s), w @ (c * c), w @ (s * c), wy @ s, wy @ c, float(np.sum(w)))


class Scan:
    """Sinusoid scans at fixed positions for many weightings (one per fold): the sin/cos tables
    are computed once per leg."""

    def __init__(self, ux: np.ndarray, freqs: np.ndarray, centre_mm: float):
        ang = 2 * np.pi * np.outer(ux - centre_mm, freqs)
        self.s, self.c = np.sin(ang), np.cos(ang)
        self.ss, self.cc, self.sc = self.s * self.s, self.c * self.c, self.s * self.c

    def amplitudes(self, resid: np.ndarray, w: np.ndarray) -> np.ndarray:
        wy = w * resid
        return _amplitudes(w @ self.ss, w @ self.cc, w @ self.sc, wy @ self.s, wy @ self.c, float(w.sum()))[0]


def _ranked(ux, m, w, centre, half, grid, scan: Scan | None, max_sinusoids: int) -> tuple[bool, np.ndarray]:
    """(trend, indices of grid frequencies ranked by the amplitude of the detrended weighted
    means `m` at positions `ux`); positions with zero weight are ignored."""
    n_pos = int(np.count_nonzero(w))
    trend = n_pos >= 2
    n0 = 1 + int(trend)
    n_max = min(max_sinusoids, (n_pos - n0) // 2, grid.size)
    if n_max <= 0 or scan is None:
        return trend, np.zeros(0, dtype=np.int64)
    b0 = PositionBasis(centre, half, (), trend).design(ux)
    sw = np.sqrt(w)
    coef = np.linalg.lstsq(b0 * sw[:, None], m * sw, rcond=None)[0]
    amp = scan.amplitudes(m - b0 @ coef, w)
    return trend, np.argsort(-amp)[:n_max]


def _design_at(ux, centre, half, trend, scan: Scan | None, idx: np.ndarray) -> np.ndarray:
    """The basis at the scan positions, from the scan's sin/cos tables (same column order as
    PositionBasis.design)."""
    cols = [np.ones(ux.size)] + ([(ux - centre) / half] if trend else [])
    if idx.size:
        sc = np.empty((ux.size, 2 * idx.size))
        sc[:, 0::2] = scan.s[:, idx]
        sc[:, 1::2] = scan.c[:, idx]
        return np.column_stack(cols + [sc])
    return np.column_stack(cols)


def _nested_predictions(b: np.ndarray, n0: int, m, w) -> np.ndarray:
    """Predictions at the rows of `b` of the nested weighted LS twins using the first n0+2j
    columns, j = 0, 1, ... (one column per j; stops where the columns become degenerate).

    With sqrt(w) b = Q R, the fit of the first k columns predicts U[:, :k] (Q' sqrt(w) m)[:k]
    where U = b R^-1 (R upper triangular keeps the nesting), so all sizes come from one
    cumulative sum."""
    sw = np.sqrt(w)
    q, r = np.linalg.qr(b * sw[:, None])
    d = np.abs(np.diag(r))
    ok = d > NESTED_RTOL * max(d.max(), 1e-300)
    k_ok = int(np.argmin(ok)) if not ok.all() else ok.size
    k_ok = n0 + 2 * ((k_ok - n0) // 2) if k_ok >= n0 else 0
    if k_ok == 0:
        return np.zeros((b.shape[0], 0))
    z = q[:, :k_ok].T @ (m * sw)
    u = solve_triangular(r[:k_ok, :k_ok], b[:, :k_ok].T, trans="T").T
    cum = np.cumsum(u * z, axis=1)
    return cum[:, n0 - 1::2]


def fit_position_twin(leg: LegData, folds: np.ndarray | None, max_sinusoids: int = MAX_SINUSOIDS,
                      error_um: np.ndarray | None = None) -> PositionFit:
    """Fit the position-only twin of one leg (um as a function of x_mm), its size chosen by
    held-out passes (`folds`: fold of every point; None = no cross-validation, trend only).
    `error_um` overrides the leg's errors (e.g. with identified effects taken out)."""
    y = leg.error_um if error_um is None else error_um
    if leg.n_targets < MIN_TARGETS_SMOOTH:
        return _fit_target_twin(leg, folds, y)
    grid = frequency_grid(leg)
    lo, hi = leg.span_mm
    centre, half = 0.5 * (lo + hi), max(0.5 * (hi - lo), 1e-9)
    ux, inv = np.unique(leg.x_mm, return_inverse=True)
    scan = Scan(ux, grid, centre) if grid.size else None
    w_all = np.bincount(inv, minlength=ux.size).astype(float)
    s_all = np.bincount(inv, y, minlength=ux.size)
    note = ""
    if folds is None:
        n_sin = 0
        cv_rms = None
        note = "one cycle only: twin size not validated on held-out data (trend only)"
    else:
        sse = None
        for f in range(int(folds.max()) + 1):
            te = folds == f
            w_te = np.bincount(inv[te], minlength=ux.size).astype(float)
            s_te = np.bincount(inv[te], y[te], minlength=ux.size)
            w = w_all - w_te
            m = np.divide(s_all - s_te, w, out=np.zeros(ux.size), where=w > 0)
            trend, idx = _ranked(ux, m, w, centre, half, grid, scan, max_sinusoids)
            pred = _nested_predictions(_design_at(ux, centre, half, trend, scan, idx), 1 + int(trend), m, w)
            # held-out SSE up to the constant sum(y^2): sum over positions of W p^2 - 2 p S
            e = (w_te[:, None] * pred**2 - 2 * pred * s_te[:, None]).sum(0)
            sse = e if sse is None else sse[: min(sse.size, e.size)] + e[: min(sse.size, e.size)]
        mse = (sse + float(y @ y)) / leg.n_points
        n_sin = int(np.flatnonzero(mse <= mse.min() + abs(mse.min()) * CV_TOLERANCE)[0])
        cv_rms = float(np.sqrt(max(mse[n_sin], 0.0)))
    m = s_all / w_all
    trend, idx = _ranked(ux, m, w_all, centre, half, grid, scan, max_sinusoids)
    idx = idx[:n_sin]
    b = _design_at(ux, centre, half, trend, scan, idx)
    sw = np.sqrt(w_all)
    bw = b * sw[:, None]
    coef = solve_gram(bw.T @ bw, bw.T @ (m * sw))
    basis = PositionBasis(centre, half, tuple(float(f) for f in grid[idx]), trend)
    return PositionFit(basis, coef, cv_rms, note, condition_number(bw.T @ bw))


def _fit_target_twin(leg: LegData, folds: np.ndarray | None, y: np.ndarray) -> PositionFit:
    basis = TargetBasis(tuple(float(v) for v in leg.targets_mm))
    b = basis.design(leg.x_mm)
    cv_rms = None
    if folds is not None:
        r = np.empty_like(y)
        for f in range(int(folds.max()) + 1):
            te = folds == f
            c = np.linalg.lstsq(b[~te], y[~te], rcond=None)[0]
            r[te] = y[te] - b[te] @ c
        cv_rms = float(np.sqrt(np.mean(r**2)))
    coef = np.linalg.lstsq(b, y, rcond=None)[0]
    return PositionFit(basis, coef, cv_rms, f"only {leg.n_targets} targets: the twin is the mean error at each target")


class Twin:
    """What the gap is measured against: `predict_um(leg, x_mm, direction)` (um, measured minus
    commanded). `kind`: fitted (on this recording) / reference / model / sim / callable."""

    kind: str = "callable"
    description: str = ""

    def predict_um(self, leg: int, x_mm, direction) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError


@dataclass
class ExternalTwin(Twin):
    """A fixed twin from a callable `predict(leg, x_mm, direction) -> error_um` (vectorised).
    `legs`: the legs it knows (None = any)."""

    predict: Callable[[int, np.ndarray, np.ndarray], np.ndarray]
    kind: str = "callable"
    description: str = ""
    legs: frozenset[int] | None = None
    info: dict = field(default_factory=dict)
    # the same twin on the error normalised to 20 degC (legs whose material temperature it
    # carries): used for the legs whose recording carries it too (station.services.diagnosis_jobs)
    normalised_twin: "ExternalTwin | None" = None

    def predict_um(self, leg: int, x_mm, direction) -> np.ndarray:
        if self.legs is not None and int(leg) not in self.legs:
            raise InputError(
                f"the twin ({self.description}) has no leg {leg} (it has legs {sorted(self.legs)}); "
                "use a twin made for the same legs"
            )
        x = np.asarray(x_mm, dtype=float)
        out = np.asarray(self.predict(int(leg), x, np.asarray(direction, dtype=float)), dtype=float)
        out = np.broadcast_to(out, x.shape).astype(float)
        if not np.all(np.isfinite(out)):
            raise InputError(f"the twin ({self.description}) predicts a non-finite error on leg {leg}")
        return out


def twin_from_model(model, source: str = "a saved model") -> ExternalTwin:
    """A fixed twin from a leg-error model object with `predict_um(leg, position_mm, direction)`
    (the fit issue's models). Legs are taken from `model.legs` when it has them."""
    legs = getattr(model, "legs", None)
    legs_set = None
    if legs is not None:
        try:
            legs_set = frozenset(int(k) for k in legs)
        except (TypeError, ValueError):
            legs_set = None
    return ExternalTwin(
        predict=lambda leg, x, d: model.predict_um(leg, x, d),
        kind="model",
        description=f"leg-error model {source}",
        legs=legs_set,
    )


def plant_twin(cfgs: dict[int, PlantConfig], description: str) -> ExternalTwin:
    """The plant's systematic error as a twin (leg number -> plant configuration): position terms
    only (direction 0, temperature at the reference, no load, time 0), so backlash, thermal, load
    and drift are left in the gap."""

    def predict(leg, x_mm, direction):
        cfg = cfgs[leg]
        return systematic_error_um(cfg, x_mm, 0.0, cfg.temp_ref_c, 0.0, 0.0)

    return ExternalTwin(predict=predict, kind="sim", description=description, legs=frozenset(cfgs))
