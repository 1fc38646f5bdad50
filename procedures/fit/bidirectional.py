"""The default leg-error model: bidirectional, least squares at the real positions, its size
chosen by cross-validation over held-out cycles.

error(x, d) = trend(u) + reversal(u, d) + stroke harmonics(x) + lead harmonics(x)

- u = (x - center) / half_span in [-1, 1] over the recorded stroke;
- trend: Legendre polynomials P_0..P_deg(u) (deg 0..3): offset, lead slope, curvature;
- reversal: -(d / 2) * (r_0 P_0(u) + ... ), so r_0 is the reversal value in um, mean error
  approaching downwards minus upwards (the plant's and the interchange data's convention; ISO
  230-2's B is its negative); degree -1 = no reversal term, 1 = reversal varying linearly;
- stroke harmonics: a sin + cos pair at wavelengths L / k, k = 1 .. K (L = stroke length: the
  wavelengths divide the stroke, so the pairs are nearly orthogonal over it), phase origin at
  the stroke centre. Fitted by least squares over the real positions, not assumed periodic, so a
  trend (in the polynomial) does not ring at the ends and irregular (ISO 230-2) spacing is fine;
- lead harmonics: a sin + cos pair at lead / h, h = 1..H, phase origin at x = 0, when the screw
  lead is known or found in the data (and the targets are dense enough to see it: lead / h >
  2.2 x spacing).

Size (deg, reversal degree, K, H) is chosen by leave-one-cycle-out cross-validation with the
one-standard-error rule on paired fold differences: the smallest model whose CV error is within
one standard error of the best. The held-out RMS reported is *nested*: for every held-out cycle
the size is chosen again without it, so the figure is not flattered by the choice.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.polynomial import legendre

from procedures.vocabulary import InputError
from procedures.fit.data import LegData
from procedures.fit.model import FitStats, LegFit

MAX_TREND_DEGREE = 3
MAX_REVERSAL_DEGREE = 1
MAX_FOURIER_TERMS = 24
MAX_LEAD_HARMONICS = 3
MIN_POINTS_PER_WAVE = 2.2  # periodic terms need wavelength > 2.2 x spacing (Nyquist: 2)
MIN_STROKE_WAVE_SPACINGS = 4.0  # stroke harmonics down to 4 target spacings


@dataclass(frozen=True)
class Basis:
    """Which terms a leg model has, and where its coordinates are anchored."""

    center_mm: float
    half_span_mm: float
    trend_degree: int
    reversal_degree: int
    wavelengths_mm: tuple[float, ...]
    lead_mm: float | None
    lead_harmonics: int

    @property
    def n_params(self) -> int:
        return (self.trend_degree + 1) + (self.reversal_degree + 1) + 2 * len(self.wavelengths_mm) + 2 * self.lead_harmonics

    def design(self, position_mm, direction) -> np.ndarray:
        """Design matrix (n points x n_params), columns in the order of `names()`."""
        x, d = np.broadcast_arrays(np.asarray(position_mm, dtype=float), np.asarray(direction, dtype=float))
        x = x.ravel()
        d = d.ravel()
        u = (x - self.center_mm) / self.half_span_mm
        cols = []
        if self.trend_degree >= 0:
            cols.append(legendre.legvander(u, self.trend_degree))
        if self.reversal_degree >= 0:
            cols.append(-0.5 * d[:, None] * legendre.legvander(u, self.reversal_degree))
        for wl in self.wavelengths_mm:
            a = 2.0 * np.pi * (x - self.center_mm) / wl
            cols.append(np.stack([np.sin(a), np.cos(a)], axis=1))
        for h in range(1, self.lead_harmonics + 1):
            a = 2.0 * np.pi * h * x / float(self.lead_mm)
            cols.append(np.stack([np.sin(a), np.cos(a)], axis=1))
        return np.concatenate(cols, axis=1) if cols else np.zeros((x.size, 0))

    def describe(self) -> str:
        parts = [f"trend deg {self.trend_degree}"]
        parts.append("no reversal" if self.reversal_degree < 0 else
                     ("reversal" if self.reversal_degree == 0 else f"reversal deg {self.reversal_degree}"))
        parts.append(f"{len(self.wavelengths_mm)} stroke harmonic(s)")
        if self.lead_mm:
            parts.append(f"{self.lead_harmonics} lead harmonic(s) of {self.lead_mm:.5g} mm")
        return ", ".join(parts) + f" ({self.n_params} parameters)"

    def to_json(self) -> dict[str, Any]:
        return {
            "center_mm": self.center_mm,
            "half_span_mm": self.half_span_mm,
            "trend_degree": self.trend_degree,
            "reversal_degree": self.reversal_degree,
            "wavelengths_mm": [float(w) for w in self.wavelengths_mm],
            "lead_mm": self.lead_mm,
            "lead_harmonics": self.lead_harmonics,
        }


def stroke_wavelengths_mm(span_mm: float, n: int) -> tuple[float, ...]:
    """The first `n` stroke-harmonic wavelengths: L / k for k = 1 .. n. (Half-integer
    harmonics, 2 L / k, were tried: they overlap on the interval and the design becomes
    ill-conditioned, cond > 1e5 with 8 pairs.)"""
    return tuple(span_mm / k for k in range(1, n + 1))


class BidirectionalLegFit(LegFit):
    method = "default"

    def __init__(self, leg: int, stroke_mm, target_spacing_mm: float, stats: FitStats, *,
                 basis: Basis, coef_um: np.ndarray, selection: dict[str, Any]):
        super().__init__(leg, stroke_mm, target_spacing_mm, stats)
        self.basis = basis
        self.coef_um = np.asarray(coef_um, dtype=float)
        self.selection = dict(selection)
        if self.coef_um.size != basis.n_params:
            raise ValueError(f"{self.coef_um.size} coefficients for a basis of {basis.n_params}")

    @property
    def reversal_um(self) -> float:
        """Reversal at mid-stroke, um: mean error approaching downwards minus upwards."""
        if self.basis.reversal_degree < 0:
            return 0.0
        i = self.basis.trend_degree + 1
        # P_k(0) is 0 for odd k, (-1)^(k/2) (k-1)!!/k!! for even k: evaluate instead of tabulating
        p0 = legendre.legvander(np.array([0.0]), self.basis.reversal_degree)[0]
        return float(self.coef_um[i:i + self.basis.reversal_degree + 1] @ p0)

    def predict_um(self, position_mm, direction=1) -> np.ndarray:
        x = self._clip(position_mm)
        x, d = np.broadcast_arrays(x, np.asarray(direction, dtype=float))
        return (self.basis.design(x, d) @ self.coef_um).reshape(x.shape)

    def describe(self) -> str:
        text = self.basis.describe()
        if self.basis.lead_harmonics and self.selection.get("lead") == "detected in the data":
            text = text.replace(" mm (", " mm, found in the data (")
        return text

    def model_json(self) -> dict[str, Any]:
        return {
            "basis": self.basis.to_json(),
            "coefficients_um": [float(c) for c in self.coef_um],
            "reversal_um": self.reversal_um,
            "selection": self.selection,
        }


def bidirectional_from_json(leg: int, stroke_mm, target_spacing_mm: float, stats: FitStats,
                            m: dict[str, Any]) -> BidirectionalLegFit:
    b = m["basis"]
    basis = Basis(
        center_mm=float(b["center_mm"]), half_span_mm=float(b["half_span_mm"]),
        trend_degree=int(b["trend_degree"]), reversal_degree=int(b["reversal_degree"]),
        wavelengths_mm=tuple(float(w) for w in b["wavelengths_mm"]),
        lead_mm=None if b["lead_mm"] is None else float(b["lead_mm"]), lead_harmonics=int(b["lead_harmonics"]),
    )
    return BidirectionalLegFit(leg, stroke_mm, target_spacing_mm, stats, basis=basis,
                               coef_um=np.array(m["coefficients_um"], dtype=float), selection=m.get("selection", {}))


def _least_squares(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least-squares coefficients by QR (cheaper than the SVD of lstsq; the designs here are
    well conditioned: the size search refuses condition numbers above 1e10 squared)."""
    q, r = np.linalg.qr(X)
    d = np.abs(np.diag(r))
    if d.size and d.min() <= 1e-10 * d.max():
        raise InputError("the model has more terms than these targets can determine; "
                         "choose a smaller size or record more targets")
    return np.linalg.solve(r, q.T @ y)


# -- finding the screw lead in the data -----------------------------------------------------------

DETECT_MARGIN = 12.0  # peak power over the noise expectation, on top of ln(independent freqs)


def pair_amplitudes(x: np.ndarray, r: np.ndarray, freqs: np.ndarray) -> np.ndarray:
    """Least-squares amplitude of a sin + cos pair at each frequency (cycles/mm) fitted to r."""
    a = 2.0 * np.pi * freqs[:, None] * x[None, :]
    s, c = np.sin(a), np.cos(a)
    ss, cc, sc = (s * s).sum(1), (c * c).sum(1), (s * c).sum(1)
    rs, rc = s @ r, c @ r
    det = ss * cc - sc * sc
    det = np.where(det > 1e-12 * ss * cc, det, np.inf)
    bs = (cc * rs - sc * rc) / det
    bc = (ss * rc - sc * rs) / det
    return np.hypot(bs, bc)


def detect_period_mm(data: LegData, shortest_stroke_wavelength_mm: float, base: "Basis") -> float | None:
    """The wavelength (mm) of a significant periodic error shorter than the stroke harmonics,
    e.g. the once-per-revolution error at the screw lead, or None.

    The residual of `base` (trend, reversal and all stroke harmonics) is averaged per cell
    (target, direction), and a sin + cos pair is fitted at each frequency between the shortest
    stroke harmonic and 1/(2.2 x spacing). The strongest peak counts when its power exceeds
    the white-noise expectation by ln(number of independent frequencies) + DETECT_MARGIN
    (false alarm below 1e-5 on noise).
    """
    spacing = data.target_spacing_mm()
    span = 2.0 * base.half_span_mm
    if spacing <= 0:
        return None
    f_lo = 1.0 / shortest_stroke_wavelength_mm + 0.5 / span
    f_hi = 1.0 / (MIN_POINTS_PER_WAVE * spacing)
    if f_hi <= f_lo:
        return None
    X = base.design(data.position_mm, data.direction)
    coef = _least_squares(X, data.error_um)
    resid = data.error_um - X @ coef
    keys = np.stack([data.position_mm, data.direction.astype(float)], 1)
    cells, ids = np.unique(keys, axis=0, return_inverse=True)
    ids = ids.ravel()
    rm = np.bincount(ids, weights=resid) / np.bincount(ids)
    xm = cells[:, 0]
    n = xm.size
    if n < 8:
        return None
    rm = rm - rm.mean()
    freqs = np.arange(f_lo, f_hi, 0.25 / span)
    if freqs.size < 2:
        return None
    amp = pair_amplitudes(xm, rm, freqs)
    k = int(np.argmax(amp))
    # refine around the peak: three rounds of a finer grid (resolution ~1e-7 of the frequency)
    lo_f, hi_f = freqs[max(k - 1, 0)], freqs[min(k + 1, freqs.size - 1)]
    for _ in range(3):
        fine = np.linspace(lo_f, hi_f, 41)
        amp_fine = pair_amplitudes(xm, rm, fine)
        j = int(np.argmax(amp_fine))
        peak_f, peak_a = float(fine[j]), float(amp_fine[j])
        lo_f, hi_f = fine[max(j - 1, 0)], fine[min(j + 1, fine.size - 1)]
    sigma2 = float(np.mean(rm**2))
    n_indep = max(1.0, (f_hi - f_lo) * span)
    # amplitude^2 of a pair fitted to white noise of variance sigma2 ~ (4 sigma2 / n) * chi2_2 / 2
    if peak_a**2 <= 4.0 * sigma2 / n * (np.log(n_indep) + DETECT_MARGIN):
        return None
    return 1.0 / peak_f


# -- size selection ----------------------------------------------------------------------------

@dataclass(frozen=True)
class _Candidate:
    trend_degree: int
    reversal_degree: int
    fourier_terms: int
    lead_harmonics: int
    columns: np.ndarray  # indices into the full design

    @property
    def n_params(self) -> int:
        return int(self.columns.size)


def _as_range(fixed: int | None, lo: int, hi: int) -> list[int]:
    return [fixed] if fixed is not None else list(range(lo, hi + 1))


def _candidates(full: Basis, trend, reversal, fourier, lead, max_params: int) -> list[_Candidate]:
    n_t = full.trend_degree + 1
    n_r = full.reversal_degree + 1
    n_f = len(full.wavelengths_mm)
    out = []
    for d, r, k, h in itertools.product(trend, reversal, fourier, lead):
        cols = list(range(0, d + 1))
        cols += list(range(n_t, n_t + r + 1))
        cols += list(range(n_t + n_r, n_t + n_r + 2 * k))
        cols += list(range(n_t + n_r + 2 * n_f, n_t + n_r + 2 * n_f + 2 * h))
        if 0 < len(cols) <= max_params:
            out.append(_Candidate(d, r, k, h, np.array(cols, dtype=np.int64)))
    # order by size, then by the grid: the selection rule prefers the first smallest
    out.sort(key=lambda c: (c.n_params, c.trend_degree, c.reversal_degree, c.fourier_terms, c.lead_harmonics))
    return out


class _FoldGrams:
    """X'X, X'y, y'y and n per fold, so that any column subset and any set of training folds
    can be solved without touching the points again."""

    MAX_COND = 1e10  # a candidate whose normal matrix is worse than this is not trusted

    def __init__(self, X: np.ndarray, y: np.ndarray, folds: np.ndarray, n_folds: int):
        p = X.shape[1]
        self.n_folds = n_folds
        self.G = np.zeros((n_folds, p, p))
        self.b = np.zeros((n_folds, p))
        self.yy = np.zeros(n_folds)
        self.n = np.zeros(n_folds, dtype=np.int64)
        for f in range(n_folds):
            m = folds == f
            Xf, yf = X[m], y[m]
            self.G[f] = Xf.T @ Xf
            self.b[f] = Xf.T @ yf
            self.yy[f] = yf @ yf
            self.n[f] = int(m.sum())

    def all_sse(self, cands: list[_Candidate], nested: bool = True) -> np.ndarray:
        """SSE[c, o, i]: candidate c scored on fold i, fitted on every fold except i and o
        (o == i: except i alone). The o != i entries serve the nested cross-validation; they
        stay inf unless `nested` (which needs at least three folds)."""
        F = self.n_folds
        # training sets: all folds but {a} (a == b) or but {a, b}; {a, b} serves two scores
        pairs = [(a, a) for a in range(F)]
        if nested and F >= 3:
            pairs += [(a, b) for a in range(F) for b in range(a + 1, F)]
        ta = np.array([a for a, _ in pairs])
        tb = np.array([b for _, b in pairs])
        drop_b = (ta != tb).astype(float)
        s_train, s_test, s_out = [], [], []  # score: which training set, which test fold, o index
        for t, (a, b) in enumerate(pairs):
            if a == b:
                s_train.append(t), s_test.append(a), s_out.append(a)
            else:
                s_train += [t, t]
                s_test += [b, a]
                s_out += [a, b]
        s_train, s_test, s_out = np.array(s_train), np.array(s_test), np.array(s_out)
        G_all = self.G.sum(axis=0)
        b_all = self.b.sum(axis=0)
        out = np.full((len(cands), F, F), np.inf)
        sizes = np.array([c.n_params for c in cands])
        # candidates of one size are solved together: one batched solve per size
        for p in np.unique(sizes):
            members = np.flatnonzero(sizes == p)
            idx = np.stack([cands[m].columns for m in members])  # (n_c, p)
            rows, cols = idx[:, :, None], idx[:, None, :]
            G_tot = G_all[rows, cols]  # (n_c, p, p)
            eig = np.linalg.eigvalsh(G_tot)  # symmetric: cheaper than the SVD behind np.linalg.cond
            good = eig[:, 0] > eig[:, -1] / self.MAX_COND
            if not good.any():
                continue
            members, idx, G_tot = members[good], idx[good], G_tot[good]
            rows, cols = idx[:, :, None], idx[:, None, :]
            Gs = np.moveaxis(self.G[:, rows, cols], 0, 1)  # (n_c, F, p, p)
            bs = np.moveaxis(self.b[:, idx], 0, 1)  # (n_c, F, p)
            Gt = G_tot[:, None] - Gs[:, ta] - drop_b[None, :, None, None] * Gs[:, tb]
            bt = b_all[idx][:, None] - bs[:, ta] - drop_b[None, :, None] * bs[:, tb]
            try:
                beta = np.linalg.solve(Gt, bt[..., None])[..., 0]
                ok = np.ones(Gt.shape[:2], dtype=bool)
            except np.linalg.LinAlgError:
                # some training set is singular (too few distinct targets left): solve one by one
                beta = np.zeros(bt.shape)
                ok = np.zeros(Gt.shape[:2], dtype=bool)
                for c_i, k_i in np.ndindex(*Gt.shape[:2]):
                    try:
                        beta[c_i, k_i] = np.linalg.solve(Gt[c_i, k_i], bt[c_i, k_i])
                        ok[c_i, k_i] = True
                    except np.linalg.LinAlgError:
                        pass
            for f in range(F):
                sel = np.flatnonzero(s_test == f)
                bsel = beta[:, s_train[sel]]  # (n_c, k, p)
                sse = (self.yy[f] - 2.0 * np.einsum("ckp,cp->ck", bsel, bs[:, f])
                       + np.einsum("ckp,cpq,ckq->ck", bsel, Gs[:, f], bsel))
                # a negative sum of squares means the subtraction lost all precision: distrust it
                sse = np.where(ok[:, s_train[sel]] & (sse >= -1e-9 * self.yy[f]), np.maximum(sse, 0.0), np.inf)
                out[members[:, None], s_out[sel][None, :], f] = sse
        return out


def _one_se_choice(sse: np.ndarray, n_test: np.ndarray, cands: list[_Candidate]) -> tuple[int, float]:
    """Index of the chosen candidate and its CV mean squared error (um^2)."""
    finite = np.all(np.isfinite(sse), axis=1)
    if not finite.any():
        raise InputError("no model size could be fitted (too few distinct targets?)")
    mse = np.where(finite, sse.sum(axis=1) / n_test.sum(), np.inf)
    best = int(np.argmin(mse))
    per_fold = np.where(finite[:, None], sse - sse[best], 0.0) / n_test  # paired: fold offsets cancel
    n_f = sse.shape[1]
    se = per_fold.std(axis=1, ddof=1) / np.sqrt(n_f) if n_f > 1 else np.zeros(len(cands))
    ok = finite & (mse - mse[best] <= se)
    ok[best] = True
    # candidates are sorted by size: the first eligible of the smallest size, lowest error
    sizes = np.array([c.n_params for c in cands])
    smallest = sizes[ok].min()
    pick = np.flatnonzero(ok & (sizes == smallest))
    chosen = int(pick[np.argmin(mse[pick])])
    return chosen, float(mse[chosen])


def fit_bidirectional_leg(
    data: LegData,
    folds: np.ndarray | None,
    *,
    lead_mm: float | str | None = "auto",
    trend_degree: int | None = None,
    reversal_degree: int | None = None,
    fourier_terms: int | None = None,
    lead_harmonics: int | None = None,
    max_fourier_terms: int = MAX_FOURIER_TERMS,
    nested: bool = True,
    where: str = "",
) -> tuple[BidirectionalLegFit, np.ndarray | None, dict[str, Any]]:
    """Fit one leg. Returns (fit with placeholder stats, held-out residuals per point or None,
    selection info). Sizes given explicitly are fixed; the others are chosen by CV over `folds`
    (None: no CV possible, then every size must be given)."""
    where = where or f"leg {data.leg}"
    lo, hi = data.stroke_mm
    if hi <= lo:
        raise InputError(f"{where}: all points are at one target ({lo:g} mm); a model needs a stroke")
    span = hi - lo
    spacing = data.target_spacing_mm()
    both_directions = np.unique(data.direction).size == 2
    n_cells = np.unique(np.stack([data.position_mm, data.direction.astype(float)], 1), axis=0).shape[0]
    max_params = max(1, n_cells - 2)  # CV guards against overfitting; keep two cells of slack

    # the largest model on offer
    n_targets = data.targets_mm().size
    k_max = max(0, min(max_fourier_terms, (n_targets - 1) // 4,
                       int(span / (MIN_STROKE_WAVE_SPACINGS * spacing)) if spacing > 0 else 0))
    wavelengths = stroke_wavelengths_mm(span, k_max)
    h_max = 0
    r_max = MAX_REVERSAL_DEGREE if both_directions else -1
    lead_source = "given"
    if isinstance(lead_mm, str):
        if lead_mm != "auto":
            raise InputError(f"{where}: screw lead must be a number of mm, 'auto' or None, got {lead_mm!r}")
        long_waves = Basis((lo + hi) / 2.0, span / 2.0, MAX_TREND_DEGREE, r_max, wavelengths, None, 0)
        shortest = wavelengths[-1] if wavelengths else span
        lead_mm = detect_period_mm(data, shortest, long_waves) if n_cells > long_waves.n_params + 8 else None
        lead_source = "detected in the data" if lead_mm else "none found"
    if lead_mm:
        h_max = max(h for h in range(0, MAX_LEAD_HARMONICS + 1) if h == 0 or lead_mm / h > MIN_POINTS_PER_WAVE * spacing)
        # a stroke harmonic within half a bin of a lead harmonic would be the same column
        lead_f = [h / lead_mm for h in range(1, h_max + 1)]
        wavelengths = tuple(w for w in wavelengths if all(abs(1.0 / w - f) > 0.5 / span for f in lead_f))
        k_max = len(wavelengths)
    full = Basis((lo + hi) / 2.0, span / 2.0, MAX_TREND_DEGREE, r_max, wavelengths, lead_mm if h_max else None, h_max)

    for name, value, top in (("trend degree", trend_degree, MAX_TREND_DEGREE),
                             ("reversal degree", reversal_degree, r_max),
                             ("number of stroke harmonics", fourier_terms, k_max),
                             ("number of lead harmonics", lead_harmonics, h_max)):
        low = -1 if name == "reversal degree" else 0
        if value is not None and not (low <= value <= top):
            raise InputError(f"{where}: {name} {value} is not available for this data (allowed {low}..{top})")

    cands = _candidates(
        full,
        _as_range(trend_degree, 0, MAX_TREND_DEGREE),
        _as_range(reversal_degree, -1, r_max),
        _as_range(fourier_terms, 0, k_max),
        _as_range(lead_harmonics, 0, h_max),
        max_params,
    )
    if not cands:
        raise InputError(f"{where}: too few distinct targets ({n_targets}) for the requested model size")

    X = full.design(data.position_mm, data.direction)
    y = data.error_um
    heldout = None
    info: dict[str, Any] = {"candidates": len(cands), "rule": "one standard error, paired over folds",
                            "lead": lead_source}
    if len(cands) > 1 and folds is None:
        raise InputError(
            f"{where}: choosing the model size needs at least two cycles (an upward and a downward "
            "pass each) to hold one out; record more cycles or fix the size (trend degree, "
            "reversal degree, stroke and lead harmonics)"
        )
    if folds is not None:
        n_folds = int(folds.max()) + 1
        grams = _FoldGrams(X, y, folds, n_folds)
        all_f = list(range(n_folds))
        nested_ok = nested and n_folds >= 3 and len(cands) > 1
        sse = grams.all_sse(cands, nested_ok)
        top = sse[:, np.arange(n_folds), np.arange(n_folds)]
        try:
            chosen, cv_mse = _one_se_choice(top, grams.n, cands)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
        info.update(folds=n_folds, cv_rms_um=float(np.sqrt(cv_mse)))
        # nested: re-choose the size without each held-out fold, then score that fold
        heldout = np.empty(data.n_points)
        for f in all_f:
            c_in = chosen
            if nested_ok:
                inner = [g for g in all_f if g != f]
                try:
                    c_in, _ = _one_se_choice(sse[:, f, inner], grams.n[inner], cands)
                except InputError:
                    pass  # nothing fits without this fold too: score the size chosen on all folds
            idx = cands[c_in].columns
            ix = np.ix_(idx, idx)
            # normal equations from the fold Grams (the candidate's conditioning was checked)
            test = folds == f
            try:
                beta = np.linalg.solve(grams.G.sum(axis=0)[ix] - grams.G[f][ix], grams.b.sum(axis=0)[idx] - grams.b[f][idx])
            except np.linalg.LinAlgError:  # singular without this fold: the minimum-norm solution
                beta = np.linalg.lstsq(X[~test][:, idx], y[~test], rcond=None)[0]
            heldout[test] = y[test] - X[test][:, idx] @ beta
        info["heldout"] = "nested cross-validation" if nested_ok else (
            "cross-validation (size fixed)" if len(cands) == 1 else
            "cross-validation that also chose the size (too few cycles to nest)")
    else:
        chosen = 0
        info["folds"] = 0
    c = cands[chosen]
    basis = Basis(full.center_mm, full.half_span_mm, c.trend_degree, c.reversal_degree,
                  full.wavelengths_mm[: c.fourier_terms], full.lead_mm if c.lead_harmonics else None,
                  c.lead_harmonics)
    coef = _least_squares(X[:, c.columns], y)
    placeholder = FitStats(data.n_points, data.n_passes, data.n_cycles, data.dropped, 0, None, None, None,
                           float(np.ptp(y)), None)
    fit = BidirectionalLegFit(data.leg, (lo, hi), spacing, placeholder, basis=basis, coef_um=coef, selection=info)
    return fit, heldout, info
