"""Significance of an effect against the scatter between passes.

Points of one pass are not independent: the pass shares an offset (re-zeroing, run-to-run
scatter), so n points of one pass carry far less information about a pass-level effect (backlash,
drift, load, a thermal offset) than n independent points. The model is therefore fitted by
feasible GLS with a random offset per pass,

    y = X b + u_pass + e,   u ~ N(0, sigma_u^2),  e ~ N(0, sigma_e^2),

(variance components from the OLS residuals, then the classic quasi-demeaning transform), and an
effect's columns are tested with a Wald F test whose denominator degrees of freedom are counted
in passes when the columns vary mostly between passes, in points when mostly within passes.

Everything is computed from the Gram matrix X'X, X'y, y'y and the pass means of X and y, so a
model costs only small matrix solves once those are known (selection.py caches them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import fdtrc


RCOND = 1e-12
"""Eigenvalues of the unit-diagonal normal matrix below RCOND x the largest are dropped (a
design condition number above 1e6): near-collinear columns (a twin with as many sinusoids as
targets, a load column that a pass offset nearly copies) then get the minimum-norm solution
instead of coefficients near 1e7 that cancel on the training passes and not on held-out ones."""


def _scaled_eig(g: np.ndarray):
    d = np.sqrt(np.clip(np.diag(g), 1e-300, None))
    w, v = np.linalg.eigh(g / np.outer(d, d))
    keep = w > RCOND * max(float(w[-1]), 1e-300)
    return d, w[keep], v[:, keep]


def solve_gram(g: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Solve the normal equations g c = h, scaled to unit diagonal first (columns of different
    units), rank-limited: directions with an eigenvalue below RCOND x the largest are left out
    (minimum-norm solution), so the solution stays bounded when columns are nearly collinear."""
    d, w, v = _scaled_eig(g)
    dd = d[:, None] if h.ndim == 2 else d
    return (v @ ((v.T @ (h / dd)) / (w[:, None] if h.ndim == 2 else w))) / dd


def inv_gram(g: np.ndarray) -> np.ndarray:
    """The (rank-limited, as solve_gram) inverse of g."""
    d, w, v = _scaled_eig(g)
    return ((v / w) @ v.T) / np.outer(d, d)


def condition_number(g: np.ndarray) -> float:
    """Condition number of the design whose normal matrix is g (columns scaled to unit norm):
    sqrt of the eigenvalue ratio of the unit-diagonal g."""
    d = np.sqrt(np.clip(np.diag(g), 1e-300, None))
    w = np.linalg.eigvalsh(g / np.outer(d, d))
    return float(np.sqrt(w[-1] / max(w[0], w[-1] * 1e-32)))


@dataclass(frozen=True)
class Gram:
    """Sufficient statistics of a regression with pass structure: g = X'X, h = X'y, yy = y'y,
    pass means mx (passes x columns) and my, pass sizes n_pass."""

    g: np.ndarray
    h: np.ndarray
    yy: float
    mx: np.ndarray
    my: np.ndarray
    n_pass: np.ndarray

    @property
    def n(self) -> int:
        return int(self.n_pass.sum())


@dataclass(frozen=True)
class GlsFit:
    """coef/cov: GLS estimates and their covariance (units of y per unit of each column).
    sigma_e_um: scatter of points within a pass; sigma_u_um: scatter of pass offsets."""

    coef: np.ndarray
    cov: np.ndarray
    sigma_e_um: float
    sigma_u_um: float
    n_points: int
    n_passes: int
    n_columns: int


def replicate_variance(resid: np.ndarray, pass_id: np.ndarray, cell: np.ndarray) -> float | None:
    """Variance of points about their (target, direction) cell after pass offsets are removed:
    the scatter of repeat passes. Unlike the within-pass scatter it does not count a shape that
    every pass repeats (e.g. a reversal that differs from target to target) as noise. None when
    no cell is repeated."""
    cnt = np.bincount(pass_id).astype(float)
    r = resid - (np.bincount(pass_id, resid) / np.maximum(cnt, 1))[pass_id]
    ids, inv = np.unique(cell, return_inverse=True)
    r = r - (np.bincount(inv, r) / np.bincount(inv))[inv]
    dof = resid.size - int(np.count_nonzero(cnt)) - ids.size + 1
    if dof <= 0:
        return None
    return float(r @ r) / dof


def random_intercept_gls(s: Gram, sigma_e2: float | None = None) -> GlsFit:
    """Feasible GLS with a random offset per pass, from the sufficient statistics. `sigma_e2`:
    the point scatter (um^2) when known from repeat passes; else the within-pass scatter."""
    n, p = s.n, s.g.shape[0]
    n_pass = int(np.count_nonzero(s.n_pass))
    cnt = np.maximum(s.n_pass, 1.0)
    c = solve_gram(s.g, s.h)
    rss = max(s.yy - float(c @ s.h), 0.0)
    rbar = s.my - s.mx @ c
    ss_between = float(np.sum(cnt * rbar**2))
    within = max(rss - ss_between, 0.0) / max(n - n_pass, 1)
    sigma_e2 = within if sigma_e2 is None else sigma_e2
    sigma_u2 = max(0.0, float(np.sum(rbar**2)) / max(n_pass - 1, 1) - sigma_e2 * float(np.mean(1.0 / cnt)))
    theta = 1.0 - np.sqrt(sigma_e2 / np.maximum(sigma_e2 + cnt * sigma_u2, 1e-300))
    k = cnt * (2 * theta - theta**2)
    gs = s.g - (s.mx * k[:, None]).T @ s.mx
    hs = s.h - (s.mx * k[:, None]).T @ s.my
    yys = s.yy - float(np.sum(k * s.my**2))
    coef = solve_gram(gs, hs)
    s2 = sigma_e2 if sigma_e2 < within else max(yys - float(coef @ hs), 0.0) / max(n - p, 1)
    cov = s2 * inv_gram(gs)
    return GlsFit(coef, cov, float(np.sqrt(sigma_e2)), float(np.sqrt(sigma_u2)), n, n_pass, p)


def between_pass_share(s: Gram, idx: list[int]) -> float:
    """Fraction of the variance of columns `idx` (after removing what the other columns explain)
    that lies in pass means: near 1 for backlash/drift/load offsets, near 0 for slopes and cycles."""
    p = s.g.shape[0]
    oth = [j for j in range(p) if j not in idx]
    g_ii = s.g[np.ix_(idx, idx)]
    m_i = s.mx[:, idx]
    if oth:
        b = solve_gram(s.g[np.ix_(oth, oth)], s.g[np.ix_(oth, idx)])
        g_ii = g_ii - s.g[np.ix_(idx, oth)] @ b
        m_i = m_i - s.mx[:, oth] @ b
    total = float(np.trace(g_ii))
    between = float(np.sum(s.n_pass[:, None] * m_i**2))
    return between / total if total > 0 else 1.0


def wald_test(fit: GlsFit, idx: list[int], between_share: float, n_effect_params: int) -> tuple[float, float, int]:
    """F statistic, p-value and denominator degrees of freedom for the columns `idx` being zero.

    Denominator df: passes minus one minus the effect parameters in the model when the columns
    vary mostly between passes (pass offsets are the noise that matters), else points minus
    columns minus passes."""
    b = fit.coef[idx]
    c = fit.cov[np.ix_(idx, idx)]
    try:
        f = float(b @ np.linalg.solve(c, b)) / len(idx)
    except np.linalg.LinAlgError:
        return 0.0, 1.0, 1
    if not np.isfinite(f) or f < 0:
        return 0.0, 1.0, 1
    if between_share >= 0.5:
        df2 = max(fit.n_passes - 1 - n_effect_params, 1)
    else:
        df2 = max(fit.n_points - fit.n_columns - fit.n_passes, 1)
    return f, float(fdtrc(len(idx), df2, f)), df2
