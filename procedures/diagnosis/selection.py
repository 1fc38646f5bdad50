"""Fitting effects on training passes, scoring them on held-out passes, and choosing them.

A leg's regression: gap = y - fixed twin = base columns (the fitted twin's position terms, or a
constant for an external twin's arbitrary zero) + effect columns + pass offsets + noise. Held-out
residuals come from fitting on all folds but one and predicting that one; a fold holds whole
passes (a pass shares its offset, so splitting one would leak it). Effects are chosen by greedy
forward selection on held-out RMS with parsimonious tie-breaking, then pruned backwards: an
effect stays only while it is significant (significance.py) and its held-out contribution
exceeds the threshold.

Speed: the rows are sorted by fold once and the base columns' Gram blocks per fold are cached,
so trying an effect costs products with its own few columns and small solves.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from procedures.diagnosis.effects import Effect, cyclic_grid
from procedures.diagnosis.legdata import LegData, per_pass_line_removed
from procedures.diagnosis.significance import (Gram, GlsFit, between_pass_share, random_intercept_gls, replicate_variance,
                                               solve_gram, wald_test)
from procedures.diagnosis.twin import _Scan

PARSIMONY = 0.03  # a simpler effect wins when it explains at least 97 % of what the best explains (held-out
# scoring already penalises a useless extra parameter, so the margin can be small)


def family(e: Effect) -> str:
    """The effect a candidate belongs to (a variant's plain effect)."""
    return getattr(e, "base", e).name


def contribution_um(rms_before_um: float, rms_after_um: float) -> float:
    """RMS of what an addition explains on held-out passes: sqrt(before^2 - after^2), um."""
    return float(np.sqrt(max(rms_before_um**2 - rms_after_um**2, 0.0)))


@dataclass
class FullFit:
    """A model fitted on all passes (GLS with pass offsets)."""

    effects: tuple[Effect, ...]
    specs: dict[str, object]
    gls: GlsFit
    slices: dict[str, slice]
    resid_um: np.ndarray
    tests: dict[str, tuple[float, float, int]] = field(default_factory=dict)  # name -> (F, p, df2)


class LegProblem:
    """The regression problem of one leg; caches held-out residuals per set of effects."""

    def __init__(self, leg: LegData, base: np.ndarray, fixed_um: np.ndarray, folds: np.ndarray | None):
        self.leg = leg
        self.base = base
        self.y = leg.error_um - fixed_um
        self.folds = folds
        n = leg.n_points
        groups = folds if folds is not None else np.zeros(n, dtype=np.int64)
        self.n_groups = int(groups.max()) + 1
        self._order = np.argsort(groups, kind="stable")
        self._bounds = np.searchsorted(groups[self._order], np.arange(self.n_groups + 1))
        self._bs = base[self._order]
        self._ys = self.y[self._order]
        self._gbb, self._hb, self._yy = [], [], []
        for a, b in self._spans():
            bb, yy = self._bs[a:b], self._ys[a:b]
            self._gbb.append(bb.T @ bb)
            self._hb.append(bb.T @ yy)
            self._yy.append(float(yy @ yy))
        self._pcount = np.bincount(leg.pass_id).astype(float)
        self._pmean_b = self._pass_means(base)
        self._pmean_y = self._pass_means(self.y)
        self._cell = leg.target_id * 2 + (leg.direction > 0)
        self._pass_group = np.array([groups[leg.pass_id == j][0] for j in range(leg.n_passes)])
        self._cv: dict[tuple[str, ...], np.ndarray] = {}
        self._cache: dict = {}
        self._full: dict = {}

    # -- building blocks ------------------------------------------------------------------------
    def _spans(self):
        return [(int(self._bounds[g]), int(self._bounds[g + 1])) for g in range(self.n_groups)]

    def _pass_means(self, v: np.ndarray) -> np.ndarray:
        cnt = np.maximum(self._pcount, 1.0)
        if v.ndim == 1:
            return np.bincount(self.leg.pass_id, v, minlength=cnt.size) / cnt
        return np.stack([np.bincount(self.leg.pass_id, v[:, j], minlength=cnt.size) for j in range(v.shape[1])], 1) / cnt[:, None]

    def _blocks(self, e: np.ndarray):
        """Per-fold Gram matrices and X'y of [base, e] (e in recording order)."""
        es = e[self._order]
        nb, q = self.base.shape[1], e.shape[1]
        gs = np.empty((self.n_groups, nb + q, nb + q))
        hs = np.empty((self.n_groups, nb + q))
        for g, (a, b) in enumerate(self._spans()):
            bb, ee, yy = self._bs[a:b], es[a:b], self._ys[a:b]
            gbe = bb.T @ ee
            gs[g, :nb, :nb] = self._gbb[g]
            gs[g, :nb, nb:] = gbe
            gs[g, nb:, :nb] = gbe.T
            gs[g, nb:, nb:] = ee.T @ ee
            hs[g, :nb] = self._hb[g]
            hs[g, nb:] = ee.T @ yy
        return gs, hs

    def _gls_blocks(self, e: np.ndarray, gs: np.ndarray, hs: np.ndarray):
        """The per-fold blocks quasi-demeaned for a random offset per pass (GLS): the fold fits
        then use the information within passes (e.g. drift and temperature change during a
        pass) instead of letting pass offsets dilute it. Variance components from the model
        fitted on all passes."""
        xm = np.column_stack([self._pmean_b, self._pass_means(e)]) if e.shape[1] else self._pmean_b
        coef = solve_gram(gs.sum(0), hs.sum(0))
        resid = self.y - self._predict(e, coef)
        cnt = np.maximum(self._pcount, 1.0)
        rbar = self._pass_means(resid)
        s2e = replicate_variance(resid, self.leg.pass_id, self._cell)
        if s2e is None:
            s2e = float(np.sum((resid - rbar[self.leg.pass_id]) ** 2)) / max(self.leg.n_points - cnt.size, 1)
        s2u = max(0.0, float(np.sum(rbar**2)) / max(cnt.size - 1, 1) - s2e * float(np.mean(1.0 / cnt)))
        theta = 1.0 - np.sqrt(s2e / np.maximum(s2e + cnt * s2u, 1e-300))
        k = cnt * (2 * theta - theta**2)
        gs, hs = gs.copy(), hs.copy()
        for g in range(self.n_groups):
            j = self._pass_group == g
            gs[g] -= (xm[j] * k[j, None]).T @ xm[j]
            hs[g] -= (xm[j] * k[j, None]).T @ self._pmean_y[j]
        return gs, hs

    def _matrix(self, effects, specs) -> tuple[np.ndarray, dict[str, slice]]:
        cols, slices, k = [], {}, 0
        for e in effects:
            c = e.columns(self.leg, specs.get(e.name))
            cols.append(c)
            slices[e.name] = slice(k, k + c.shape[1])
            k += c.shape[1]
        if not cols:
            return np.zeros((self.leg.n_points, 0)), slices
        return np.column_stack(cols), slices

    def _predict(self, e: np.ndarray, coef: np.ndarray) -> np.ndarray:
        nb = self.base.shape[1]
        return self.base @ coef[:nb] + (e @ coef[nb:] if e.shape[1] else 0.0)

    # -- the cyclic wavelength ----------------------------------------------------------------
    def _per_pass_line_removed(self, v: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return per_pass_line_removed(self.leg, v, rows)

    def _search_cyclic(self, train_groups: list[int]) -> float | None:
        """Wavelength (mm) of the strongest sinusoid of position on the training rows, after a
        line per pass is taken out (so no other effect can bias it): a sinusoid scan of the
        per-position means, refined by Gauss-Newton on the frequency. Cached per fold."""
        key = ("cyclic", tuple(train_groups))
        if key in self._cache:
            return self._cache[key]
        groups = self.folds if self.folds is not None else np.zeros(self.leg.n_points, int)
        rows = np.flatnonzero(np.isin(groups, train_groups))
        x = self.leg.x_mm[rows]
        yr = self._per_pass_line_removed(self.y[rows], rows)
        if "cyc_scan" not in self._cache:
            ux = np.unique(self.leg.x_mm)
            grid = cyclic_grid(self.leg, oversample=2)  # the Gauss-Newton step below refines
            self._cache["cyc_scan"] = (ux, grid, _Scan(ux, grid, 0.0) if grid.size else None)
        ux, grid, scan = self._cache["cyc_scan"]
        if scan is None:
            self._cache[key] = None
            return None
        inv = np.searchsorted(ux, x)
        w = np.bincount(inv, minlength=ux.size).astype(float)
        m = np.divide(np.bincount(inv, yr, minlength=ux.size), w, out=np.zeros(ux.size), where=w > 0)
        k = int(np.argmax(scan.amplitudes(m, w)))
        step = grid[1] - grid[0] if grid.size > 1 else grid[0]
        f0 = f = float(grid[k])
        a = b = None
        for _ in range(8):
            ang = 2 * np.pi * f * x
            sn, cs = np.sin(ang), np.cos(ang)
            cols = [sn, cs] if a is None else [sn, cs, 2 * np.pi * x * (a * cs - b * sn)]
            z = self._per_pass_line_removed(np.column_stack(cols), rows)
            coef = solve_gram(z.T @ z, z.T @ yr)
            if a is not None:
                df = float(np.clip(coef[2], -0.5 * step, 0.5 * step))
                f = float(np.clip(f + df, f0 - step, f0 + step))
                if abs(df) < 1e-7 * f:
                    break
            a, b = float(coef[0]), float(coef[1])
        self._cache[key] = 1.0 / f
        return 1.0 / f

    def _specs(self, effects, train_groups: list[int]) -> dict[str, object]:
        specs: dict[str, object] = {}
        for e in effects:
            if e.name == "cyclic":
                specs["cyclic"] = self._search_cyclic(train_groups)
            elif getattr(e, "searched", False):  # a variant with a scanned parameter (the wind-up length)
                key = (getattr(e, "search_key", e.name), tuple(train_groups))  # a stacked variant shares its part's
                if key not in self._cache:
                    groups = self.folds if self.folds is not None else np.zeros(self.leg.n_points, int)
                    self._cache[key] = e.search(self.leg, self.y, np.flatnonzero(np.isin(groups, train_groups)))
                specs[e.name] = self._cache[key]
        return specs

    # -- held-out scoring ---------------------------------------------------------------------
    def heldout_residuals(self, effects: tuple[Effect, ...]) -> np.ndarray:
        """Residual of every point, predicted by the model fitted without its fold (um)."""
        if self.folds is None:
            raise ValueError("no folds: the leg has too few passes to hold any out")
        key = tuple(sorted(e.name for e in effects))
        if key in self._cv:
            return self._cv[key]
        out = np.empty(self.leg.n_points)
        all_groups = list(range(self.n_groups))
        searched = any(e.name == "cyclic" or getattr(e, "searched", False) for e in effects)
        if not searched:
            e, _ = self._matrix(effects, {})
            gs, hs = self._gls_blocks(e, *self._blocks(e))
            gt, ht = gs.sum(0), hs.sum(0)
        for g in all_groups:
            te = self.folds == g
            if searched:
                train = [j for j in all_groups if j != g]
                specs = self._specs(effects, train)
                e, _ = self._matrix(effects, specs)
                gs, hs = self._gls_blocks(e, *self._blocks(e))
                gt, ht = gs.sum(0), hs.sum(0)
            coef = solve_gram(gt - gs[g], ht - hs[g])
            nb = self.base.shape[1]
            out[te] = self.y[te] - self.base[te] @ coef[:nb] - (e[te] @ coef[nb:] if e.shape[1] else 0.0)
        self._cv[key] = out
        return out

    def cv_rms(self, effects: tuple[Effect, ...]) -> float:
        r = self.heldout_residuals(effects)
        return float(np.sqrt(np.mean(r**2)))

    # -- fits on all passes ---------------------------------------------------------------------
    def effect_part_um(self, fit: FullFit) -> np.ndarray:
        """The fitted effects' contribution at every point (um), without the base terms."""
        e_all, _ = self._matrix(fit.effects, fit.specs)
        nb = self.base.shape[1]
        return e_all @ fit.gls.coef[nb:] if e_all.shape[1] else np.zeros(self.leg.n_points)

    def full_fit(self, effects: tuple[Effect, ...], bonferroni: dict[str, int] | None = None) -> FullFit:
        """GLS fit on all passes, with a Wald test of each effect's columns."""
        key = (tuple(e.name for e in effects), tuple(sorted((bonferroni or {}).items())))
        if key not in self._full:
            self._full[key] = self._full_fit(effects, bonferroni)
        return self._full[key]

    def _full_fit(self, effects, bonferroni) -> FullFit:
        specs = self._specs(effects, list(range(self.n_groups)))
        e_all, slices = self._matrix(effects, specs)
        gs, hs = self._blocks(e_all)
        stats = Gram(gs.sum(0), hs.sum(0), float(sum(self._yy)),
                     np.column_stack([self._pmean_b, self._pass_means(e_all)]) if e_all.shape[1] else self._pmean_b,
                     self._pmean_y, self._pcount)
        nb = self.base.shape[1]
        coef = solve_gram(stats.g, stats.h)
        s2 = replicate_variance(self.y - self._predict(e_all, coef), self.leg.pass_id, self._cell)
        gls = random_intercept_gls(stats, s2)
        fit = FullFit(tuple(effects), specs, gls, {k: slice(s.start + nb, s.stop + nb) for k, s in slices.items()},
                      self.y - self._predict(e_all, gls.coef))
        n_eff = sum(e.n_params for e in effects)
        for e in effects:
            s = fit.slices[e.name]
            idx = list(range(s.start, s.stop))
            f, p, df2 = wald_test(gls, idx, between_pass_share(stats, idx), n_eff)
            if bonferroni and e.name in bonferroni:
                p = min(1.0, p * bonferroni[e.name])  # a scanned wavelength: look-elsewhere effect
            fit.tests[e.name] = (f, p, df2)
            n_extra = getattr(e, "n_extra", 0)
            if n_extra:  # a variant: its extra columns alone
                for part, sl in (e.part_slices().items() if hasattr(e, "part_slices") else ()):
                    pidx = idx[sl]  # a stacked variant: each part's extra columns alone too
                    fit.tests[f"{e.name}+{part}"] = wald_test(gls, pidx, between_pass_share(stats, pidx), n_eff)
                idx = idx[-n_extra:]
                fit.tests[e.name + "+"] = wald_test(gls, idx, between_pass_share(stats, idx), n_eff)
        return fit

    def unresolvable(self, e: Effect) -> str | None:
        """Why the sampling cannot resolve candidate `e`'s scanned parameter on this leg (a wind-up
        shorter than the target spacing), from the scan on all passes; None when it can."""
        check = getattr(e, "unresolvable", None)
        if check is None:
            return None
        spec = self._specs((e,), list(range(self.n_groups))).get(e.name)
        return check(self.leg, spec)


@dataclass
class Evaluation:
    """One candidate scored on top of a set of already chosen effects."""

    name: str
    rms_before_um: float
    rms_after_um: float
    contribution_um: float
    p_value: float
    f_stat: float
    df2: int

    def qualifies(self, threshold_um: float, alpha: float) -> bool:
        return self.p_value < alpha and self.contribution_um > threshold_um


def evaluate(problem: LegProblem, chosen: tuple[Effect, ...], cand: Effect, bonferroni) -> Evaluation:
    before = problem.cv_rms(chosen)
    after = problem.cv_rms(chosen + (cand,))
    fit = problem.full_fit(chosen + (cand,), bonferroni)
    f, p, df2 = fit.tests[cand.name]
    return Evaluation(cand.name, before, after, contribution_um(before, after), p, f, df2)


def _best_pair(problem: LegProblem, chosen, rest, threshold_um, alpha, bonferroni, significant: set[str]):
    """Two effects that only help together (e.g. a thermal offset and a drift of opposite sign
    that cancel in the mean): both significant in the joint model and each adding more than the
    threshold on held-out passes once the other is in; at least one of them `significant` alone.
    None when no pair qualifies."""
    after_chosen = problem.cv_rms(chosen)
    best, best_rms = None, None
    rest = [c for c in rest if family(c) == c.name]  # pairs of plain effects only
    for i, a in enumerate(rest):
        for b in rest[i + 1:]:
            if a.name not in significant and b.name not in significant:
                continue
            both = chosen + (a, b)
            after = problem.cv_rms(both)
            if contribution_um(after_chosen, after) <= threshold_um:
                continue
            fit = problem.full_fit(both, bonferroni)
            if fit.tests[a.name][1] >= alpha or fit.tests[b.name][1] >= alpha:
                continue
            if min(contribution_um(problem.cv_rms(chosen + (b,)), after),
                   contribution_um(problem.cv_rms(chosen + (a,)), after)) <= threshold_um:
                continue
            if best_rms is None or after < best_rms:
                best, best_rms = (a, b), after
    return best


def select_effects(problem: LegProblem, candidates: list[Effect], threshold_um: float, alpha: float,
                   bonferroni: dict[str, int] | None = None) -> tuple[tuple[Effect, ...], list[str]]:
    """Greedy forward selection (a pair when no single effect qualifies), then backward pruning.
    Returns (chosen effects, log lines)."""
    chosen: tuple[Effect, ...] = ()
    log: list[str] = []
    while True:
        taken = {family(c) for c in chosen}  # an effect and its variants exclude each other
        rest = [c for c in candidates if family(c) not in taken]
        if not rest:
            break
        evals = [(c, evaluate(problem, chosen, c, bonferroni)) for c in rest]
        ok = [(c, ev) for c, ev in evals if ev.qualifies(threshold_um, alpha)]
        if not ok:
            # pairs only with a partner that is at least significant alone
            sig = {c.name for c, ev in evals if ev.p_value < alpha}
            pair = _best_pair(problem, chosen, rest, threshold_um, alpha, bonferroni, sig)
            if pair is None:
                break
            log.append(f"add {pair[0].name} + {pair[1].name} together (neither helps alone: they partly cancel)")
            chosen = chosen + pair
            continue
        best = max(ev.contribution_um for _, ev in ok)
        near = [(c, ev) for c, ev in ok if ev.contribution_um >= (1 - PARSIMONY) * best]
        c, ev = min(near, key=lambda t: (t[0].n_params, -t[1].contribution_um))
        log.append(f"add {c.name}: held-out {ev.rms_before_um:.4f} -> {ev.rms_after_um:.4f} um, p={ev.p_value:.2g}")
        chosen = chosen + (c,)
    chosen, plog = prune(problem, chosen, threshold_um, alpha, bonferroni)
    return chosen, log + plog


def prune(problem: LegProblem, chosen: tuple[Effect, ...], threshold_um: float, alpha: float,
          bonferroni: dict[str, int] | None = None) -> tuple[tuple[Effect, ...], list[str]]:
    """Backward pruning: drop the weakest effect while any no longer earns its place (not
    significant, or adding no more than the threshold on held-out passes once the others are in)."""
    log: list[str] = []
    while len(chosen) > 1:
        fit = problem.full_fit(chosen, bonferroni)
        after = problem.cv_rms(chosen)
        weakest, worst = None, None
        for c in chosen:
            without = tuple(e for e in chosen if e is not c)
            contrib = contribution_um(problem.cv_rms(without), after)
            p = fit.tests[c.name][1]
            if p >= alpha or contrib <= threshold_um:
                if worst is None or contrib < worst:
                    weakest, worst = c, contrib
        if weakest is None:
            break
        log.append(f"drop {weakest.name}: adds only {worst:.4f} um once the others are in")
        chosen = tuple(e for e in chosen if e is not weakest)
    return chosen, log


def refine_variants(problem: LegProblem, chosen: tuple[Effect, ...], variants: dict, threshold_um: float, alpha: float,
                    bonferroni: dict[str, int] | None = None, external: bool = False) -> tuple[tuple[Effect, ...], list[str]]:
    """Each named effect as the variant (variants.py) that earns it, else plain: a variant stays
    only when its extra columns are significant on their own and add more than the threshold
    on held-out passes over the plain effect; the best such variant wins. Returns (effects, log)."""
    log: list[str] = []
    out = list(chosen)
    for i, e in enumerate(chosen):
        plain = getattr(e, "base", e)
        with_plain = tuple(out[:i] + [plain] + out[i + 1:])
        rms_plain = problem.cv_rms(with_plain)
        best, best_rms = plain, rms_plain
        for v in variants.get(plain.name, ()):
            if v.applicable(problem.leg, external) is not None:
                continue
            trial = tuple(out[:i] + [v] + out[i + 1:])
            after = problem.cv_rms(trial)
            p = problem.full_fit(trial, bonferroni).tests[v.name + "+"][1]
            if p < alpha and contribution_um(rms_plain, after) > threshold_um and after < best_rms:
                best, best_rms = v, after
        if best is not e:
            log.append(f"{plain.name} is {'plain' if best is plain else 'the ' + best.variant + ' variant'}: held-out "
                       f"{problem.cv_rms(tuple(out)):.4f} -> {best_rms:.4f} um")
        out[i] = best
    return tuple(out), log


# -- joint selection (issue 35) -----------------------------------------------------------------
MAX_COMBINATIONS = 64  # joint variant choices tried per set, beyond this one effect at a time
CLOSE_ALTERNATIVES = 3  # rejected sets reported per leg


def label(e: Effect) -> str:
    """The effect as the report names it, with its variant: `backlash/temperature+position`."""
    v = getattr(e, "variant", None)
    return f"{family(e)}/{v}" if v else e.name


def _stacked_alone(v: Effect, variants: dict) -> list[tuple[str, Effect]]:
    """For a stacked variant: (part, the variant without that part) for each of its parts."""
    parts = getattr(v, "parts", ())
    if not parts:
        return []
    by_variant = {getattr(o, "variant", None): o for o in variants.get(family(v), ())}
    out = []
    for p in parts:
        rest = "+".join(q.variant for q in parts if q is not p)
        if rest in by_variant:
            out.append((p.variant, by_variant[rest]))
    return out


def refine_jointly(problem: LegProblem, chosen: tuple[Effect, ...], variants: dict, threshold_um: float, alpha: float,
                   bonferroni: dict[str, int] | None = None, external: bool = False
                   ) -> tuple[tuple[Effect, ...], list[str], list[tuple[tuple[Effect, ...], float, str]]]:
    """Every named effect plain or as one of its variants (stacked ones included), the choices
    compared as sets on held-out passes (not one effect at a time). A variant counts only when its
    extra columns are significant on their own and add more than the threshold over the plain
    effect in that set; a stacked variant also needs each part significant and adding more than
    the threshold over the variant without it. The valid set with the lowest held-out RMS wins.
    Returns (effects, log, rejected: (set, held-out RMS, why) for the report)."""
    import itertools

    options = []
    for e in chosen:
        plain = getattr(e, "base", e)
        opts = [plain] + [v for v in variants.get(plain.name, ())
                          if v.applicable(problem.leg, external) is None and problem.unresolvable(v) is None]
        options.append(opts)
    # a stacked variant only where each of its parts alone improves on the plain effect (the others
    # as named): saves its fits on the many legs where no variant helps
    for i, e in enumerate(chosen):
        plain = options[i][0]
        rms_plain = problem.cv_rms(tuple(chosen[:i]) + (plain,) + tuple(chosen[i + 1:]))
        helps = {getattr(v, "variant", None) for v in options[i][1:] if not hasattr(v, "parts")
                 and problem.cv_rms(tuple(chosen[:i]) + (v,) + tuple(chosen[i + 1:])) < rms_plain}
        options[i] = [v for v in options[i] if not hasattr(v, "parts") or all(p.variant in helps for p in v.parts)]
    n_comb = int(np.prod([len(o) for o in options])) if options else 1
    if n_comb > MAX_COMBINATIONS:
        out, log = refine_variants(problem, chosen, variants, threshold_um, alpha, bonferroni, external)
        return out, log, []
    results = []
    for combo in itertools.product(*options):
        rms = problem.cv_rms(combo)
        why = None
        for i, v in enumerate(combo):
            if v is options[i][0]:
                continue
            fit = problem.full_fit(combo, bonferroni)
            if fit.tests[v.name + "+"][1] >= alpha:
                why = f"{label(v)}: its extra terms are not significant (p = {fit.tests[v.name + '+'][1]:.2g})"
                break
            gain = contribution_um(problem.cv_rms(combo[:i] + (options[i][0],) + combo[i + 1:]), rms)
            if gain <= threshold_um:
                why = f"{label(v)} adds only {gain:.3g} um over the plain {family(v)}"
                break
            for part, alone in _stacked_alone(v, variants):
                p = fit.tests[f"{v.name}+{part}"][1]
                gain = contribution_um(problem.cv_rms(combo[:i] + (alone,) + combo[i + 1:]), rms)
                if p >= alpha or gain <= threshold_um:
                    why = f"{label(v)}: its {part} part adds only {gain:.3g} um (p = {p:.2g})"
                    break
            if why:
                break
        results.append((combo, rms, why))
    valid = [r for r in results if r[2] is None]
    best = min(valid, key=lambda r: (r[1], sum(e.n_params for e in r[0])))
    log = []
    if best[0] != tuple(chosen):
        log.append(f"variants chosen jointly: {', '.join(label(e) for e in best[0])}: held-out "
                   f"{problem.cv_rms(tuple(chosen)):.4f} -> {best[1]:.4f} um")
    rejected = [(c, r, why or "explains less on held-out passes") for c, r, why in results if c != best[0]]
    return best[0], log, rejected


MAX_EXCHANGES = 3  # rounds of exchanges per leg (each one scores every neighbouring set)


EXCHANGES_REFINED = 2  # the best exchange sets whose variants are also chosen anew before they are compared
EXCHANGE_REFINE_WITHIN = 2.0  # ... when their held-out RMS is within this factor of the named set's (speed)


def _exchange(problem: LegProblem, chosen: tuple[Effect, ...], candidates: list[Effect], threshold_um: float,
              alpha: float, bonferroni, refine=None
              ) -> tuple[tuple[Effect, ...], list[str], list[tuple[tuple[Effect, ...], float, str]]]:
    """Sets next to `chosen`: one or two of its effects replaced by one candidate of another
    effect (confounded candidates: thermal for drift, or for drift and scale, while a leg warms).
    The one with the lowest held-out RMS replaces `chosen` when it is lower and every effect in it
    still earns its place (significant, more than the threshold once the others are in); repeated
    while that improves. Returns (effects, log, the sets scored: (set, held-out RMS, why not))."""
    import itertools

    log: list[str] = []
    scored: dict[frozenset, tuple[tuple[Effect, ...], float, str]] = {}
    for _ in range(MAX_EXCHANGES):
        now = problem.cv_rms(chosen)
        best, best_rms = None, now
        drops = [(c,) for c in chosen] + (list(itertools.combinations(chosen, 2)) if len(chosen) >= 2 else [])
        for out in drops:
            keep = tuple(c for c in chosen if c not in out)
            taken = {family(c) for c in keep}
            for c in candidates:
                if family(c) in taken or (len(out) == 1 and family(c) == family(out[0])):
                    continue  # a variant of the same effect: refine_jointly's choice
                trial = keep + (c,)
                rms = problem.cv_rms(trial)
                why = "explains less on held-out passes"
                if rms < best_rms:  # only a better set needs the (costlier) check of each effect's place
                    pruned = prune(problem, trial, threshold_um, alpha, bonferroni)[0]
                    if pruned == trial:
                        best, best_rms = (out, c, trial), rms
                    else:
                        why = f"{', '.join(label(e) for e in trial if e not in pruned)} does not earn its place in it"
                scored.setdefault(frozenset(e.name for e in trial), (trial, rms, why))
        if refine is not None:
            # a confounded exchange may pay only with other variants of the effects kept (thermal for
            # drift and scale once the reversal also grows with temperature): the best few exchange sets
            # get their variants chosen anew
            here = {frozenset(e.name for e in chosen)}
            tried = sorted((t for t in scored.values() if frozenset(e.name for e in t[0]) not in here
                            and t[1] < EXCHANGE_REFINE_WITHIN * now), key=lambda t: t[1])[:EXCHANGES_REFINED]
            for trial, _rms, _why in tried:
                again = refine(trial)
                rms = problem.cv_rms(again)
                if rms < best_rms and prune(problem, again, threshold_um, alpha, bonferroni)[0] == again:
                    best, best_rms = (tuple(e for e in chosen if e not in trial), again[-1], again), rms
                scored.setdefault(frozenset(e.name for e in again), (again, rms, "explains less on held-out passes"))
        if best is None:
            break
        out, c, new = best
        log.append(f"exchange {', '.join(label(e) for e in chosen)} for {', '.join(label(e) for e in new)}: held-out "
                   f"{now:.4f} -> {best_rms:.4f} um")
        chosen = new
    return chosen, log, list(scored.values())


def _refine(problem, chosen, variants, threshold_um, alpha, bonferroni, external):
    """Variants chosen jointly, then pruned; again when the prune dropped an effect."""
    log, rejected = [], []
    for _round in range(2):
        chosen, vlog, rejected = refine_jointly(problem, chosen, variants, threshold_um, alpha, bonferroni, external)
        prlog = []
        if vlog:  # a variant can make another effect redundant (a wind-up's ends look like a scale error)
            chosen, prlog = prune(problem, chosen, threshold_um, alpha, bonferroni)
        log += vlog + prlog
        if not prlog:
            break  # else the variants are chosen again without the effect dropped
    return chosen, log, rejected


def select_jointly(problem: LegProblem, candidates: list[Effect], variants: dict, threshold_um: float, alpha: float,
                   bonferroni: dict[str, int] | None = None, external: bool = False
                   ) -> tuple[tuple[Effect, ...], list[str], list[dict]]:
    """Effects and their variants chosen as sets on held-out passes (issue 35): the forward
    selection and pruning of `select_effects` (stacked variants left out of it), then the named
    effects' variants chosen jointly (`refine_jointly`), then exchanges of confounded effects
    (`_exchange`, the variants chosen again after one). Candidates whose scanned parameter the
    sampling cannot resolve (a wind-up shorter than the target spacing) are not tried. Returns
    (effects, log, the closest sets rejected: effects, held-out RMS, margins, reason)."""
    log: list[str] = []
    usable = []
    for c in candidates:
        why = problem.unresolvable(c)
        if why is None:
            usable.append(c)
        else:
            log.append(f"not tried: {label(c)}: {why}")
    chosen, flog = select_effects(problem, usable, threshold_um, alpha, bonferroni)
    log += flog
    rejected: list[tuple[tuple[Effect, ...], float, str]] = []
    if chosen:
        # exchanges before the variants are chosen (a variant fitted alongside drift and scale can
        # keep thermal out) and after (a variant can make another exchange worth it)
        def refine(effects):
            return _refine(problem, effects, variants, threshold_um, alpha, bonferroni, external)[0]

        chosen, xlog, scored = _exchange(problem, chosen, usable, threshold_um, alpha, bonferroni, refine)
        log += xlog
        rejected += scored
        for _round in range(2):
            chosen, rlog, again = _refine(problem, chosen, variants, threshold_um, alpha, bonferroni, external)
            log += rlog
            rejected += again
            if not rlog:
                break
            chosen, xlog, scored = _exchange(problem, chosen, usable, threshold_um, alpha, bonferroni, refine)
            log += xlog
            rejected += scored
            if not xlog:
                break
    after = problem.cv_rms(chosen)
    out, seen = [], {frozenset(e.name for e in chosen)}
    for effects, rms, why in sorted(rejected, key=lambda t: t[1]):
        key = frozenset(e.name for e in effects)
        if key in seen:
            continue
        seen.add(key)
        out.append({"effects": [label(e) for e in effects], "heldout_rms_after_um": rms, "worse_by_um": rms - after,
                    "margin_um": contribution_um(rms, after) if rms >= after else -contribution_um(after, rms),
                    "reason": why})
        if len(out) >= CLOSE_ALTERNATIVES:
            break
    return chosen, log, out
