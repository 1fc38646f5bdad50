"""Diagnosis of the gap between a twin and a recording: where, which effect, how far.

`diagnose(points, twin=None)` returns a JSON-able report (see docs/diagnosis.md):

    {"format": "station-diagnosis", "version": 2, "recording": {...}, "twin": {...},
     "settings": {...},
     "findings": [{"leg": 2, "effect": "backlash", "parameters": {"reversal_um": 1.23},
                   "uncertainty": {"reversal_um": 0.02}, "heldout_rms_before_um": 0.61,
                   "heldout_rms_after_um": 0.07, ...}, ...],
     "legs": {"2": {...where..., "noise_floor_um": 0.25, "repeat_scatter_after_effects_um": 0.05,
                    "combined": {...}, "candidates": [...], "cannot_conclude": [...]}},
     "notes": [...]}

`noise_floor_um` is the noise floor of `station fit` (procedures.fit.noise, the same function);
`repeat_scatter_after_effects_um` the scatter of repeat passes left once the twin and the named
effects are taken out (version 1 called it `noise_floor_um`). Names: docs/figures.md.

Units are in the keys; error = measured minus commanded (um); no NaN anywhere (a value that
cannot be computed is null with a reason beside it).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from procedures.diagnosis.aliasing import sampling_warning
from procedures.diagnosis.blas import single_threaded_blas
from procedures.diagnosis.effects import EFFECTS, Cyclic, Effect
from procedures.diagnosis.legdata import LegData, split_legs
from procedures.diagnosis.probe_reversal import FixedReversal, fixed_reversal, probe_points
from procedures.diagnosis.selection import LegProblem, contribution_um, evaluate, select_jointly
from procedures.diagnosis.variants import VARIANTS
from procedures.diagnosis.unexplained import unexplained
from procedures.diagnosis.twin import TargetBasis, Twin, fit_position_twin
from procedures.diagnosis.where import breakdown, outlier_mask, repeatability_um
from procedures.vocabulary import InputError
from procedures.fit.noise import noise_floor
from procedures.io.recording.schema import FLAG_ANCHOR, FLAG_PROBE

FORMAT = "station-diagnosis"
VERSION = 2  # 2: `noise_floor_um` is the noise floor of station fit; version 1's is repeat_scatter_after_effects_um


@dataclass(frozen=True)
class DiagnosisSettings:
    """threshold_um: an effect is named only when its held-out RMS contribution exceeds this;
    alpha: significance level of the pass-level test; lead_mm: screw lead marked in the spectrum
    (None = none); max_folds: cross-validation folds (whole passes); regions: stroke regions in
    the breakdown; effects: the candidate effects tried."""

    threshold_um: float = 0.1
    alpha: float = 1e-3
    lead_mm: float | None = 5.0
    max_folds: int = 12
    regions: int = 4
    effects: tuple[str, ...] = tuple(EFFECTS)
    holdout: str = "cycle"
    motor_turn_mm: float | None = None  # travel per motor turn (lead / gear ratio): checked as an alias source

    def __post_init__(self):
        unknown = [e for e in self.effects if e not in EFFECTS]
        if unknown:
            raise InputError(f"unknown effect(s) {unknown}; known: {', '.join(EFFECTS)}")
        if not self.threshold_um >= 0:
            raise InputError(f"threshold_um must be >= 0, got {self.threshold_um}")
        if not 0 < self.alpha < 1:
            raise InputError(f"alpha must be between 0 and 1, got {self.alpha}")
        if self.lead_mm is not None and not self.lead_mm > 0:
            raise InputError(f"lead_mm must be positive, got {self.lead_mm}")
        if self.motor_turn_mm is not None and not self.motor_turn_mm > 0:
            raise InputError(f"motor_turn_mm must be positive, got {self.motor_turn_mm}")
        if self.holdout not in ("cycle", "pass"):
            raise InputError(f"holdout must be 'cycle' or 'pass', got {self.holdout!r}")
        if self.regions < 1 or self.max_folds < 2:
            raise InputError("regions must be >= 1 and max_folds >= 2")


@dataclass
class LegContext:
    """What the diagnosis of one leg works on (used by the self-check for its oracle)."""

    leg: LegData
    problem: LegProblem
    fixed_um: np.ndarray
    external: bool
    twin_info: dict = field(default_factory=dict)


def prepare_leg(leg: LegData, twin: Twin | None, settings: DiagnosisSettings,
                twin_error_um: np.ndarray | None = None) -> LegContext:
    """Set up the regression of one leg against the twin (fitted here when `twin` is None, on
    `twin_error_um` when given: the errors with already identified effects taken out)."""
    folds = leg.folds(settings.max_folds, settings.holdout)
    if twin is None:
        pfit = fit_position_twin(leg, folds, error_um=twin_error_um)
        base = pfit.basis.design(leg.x_mm)
        fixed = np.zeros(leg.n_points)
        if isinstance(pfit.basis, TargetBasis):
            info = {"kind": "fitted", "form": "target means", "targets": len(pfit.basis.knots_mm),
                    "heldout_rms_um": pfit.cv_rms_um, "note": pfit.note}
        else:
            info = {"kind": "fitted", "form": "trend + sinusoids", "trend": pfit.basis.trend,
                    "sinusoids": len(pfit.basis.freqs_per_mm),
                    "wavelengths_mm": [1.0 / f for f in pfit.basis.freqs_per_mm], "heldout_rms_um": pfit.cv_rms_um,
                    "condition_number": pfit.condition_number}
        if pfit.cv_rms_um is None:
            info["heldout_rms_note"] = pfit.note
    else:
        fixed = twin.predict_um(leg.leg, leg.x_mm, leg.direction)
        base = np.ones((leg.n_points, 1))  # an external twin has its own zero
        info = {"kind": twin.kind, "offset_um": float(np.mean(leg.error_um - fixed))}
    return LegContext(leg, LegProblem(leg, base, fixed, folds), fixed, twin is not None, info)


def _cannot_conclude(leg: LegData, settings: DiagnosisSettings, external: bool) -> list[str]:
    out = []
    if leg.n_cycles < 2:
        out.append(f"only {leg.n_cycles} cycle: no pass can be held out, so no effect can be tested; "
                   "the breakdown describes the gap only")
    elif leg.n_cycles < 3:
        out.append("only 2 cycles: held-out scores rest on 2 folds; treat any finding as indicative")
    if leg.n_targets < 8:
        sp = leg.spacing_mm
        text = (f"only {leg.n_targets} distinct targets ({sp:.3g} mm apart): "
                + ("the twin can only follow the mean error at each target, so " if not external else "")
                + f"the shape between targets, periodic errors shorter than {2 * sp:.3g} mm")
        if settings.lead_mm and settings.lead_mm < 2 * sp:
            text += f" (the {settings.lead_mm:g} mm screw lead among them)"
        text += " and a cyclic error cannot be resolved"
        if not external:
            text += "; a scale error cannot be told from the twin's own slope"
        out.append(text)
    if leg.n_cycles >= 2 and leg.n_passes < 12:
        out.append(f"only {leg.n_passes} passes: pass-level effects (backlash, drift, load, a thermal offset) are "
                   f"tested against the scatter of {leg.n_passes} pass offsets, so only effects well above that "
                   "scatter can be named")
    if not leg.has_time:
        out.append("no time recorded: drift is tested against pass order (um per pass), which assumes the passes "
                   "followed each other at a steady pace")
    if not leg.has_temp:
        out.append("no material temperature recorded: thermal expansion cannot be tested")
    if not leg.has_load:
        out.append("no axial load recorded: compliance cannot be tested")
    return out


TWIN_REFITS = 3  # rounds of choosing the twin again without the named effects (until it stops changing)


def _name(e: Effect) -> str:
    """The effect's name in the report (a variant carries its effect's name and says which variant)."""
    return getattr(e, "base", e).name


STEEL_PPM_PER_K = 11.5  # the default leg material (procedures/metrology/thermal.py Material)


def scale_and_temperature(scale_ppm: float, leg: LegData, twin: Twin) -> dict | None:
    """A scale found against a reference recording made at another material temperature, tied
    to the recorded difference: how many ppm per kelvin of it, against steel's expansion. None
    when either side carries no material temperature or they differ by less than 0.1 K."""
    info = (getattr(twin, "info", None) or {}).get(str(leg.leg)) or {}
    ref_c = info.get("material_temp_c")
    if ref_c is None or not leg.has_temp or info.get("basis") == "normalised":  # no temperature between them then
        return None
    here_c = float(np.mean(leg.temp_c))
    dt = here_c - ref_c
    if abs(dt) < 0.1:
        return None
    per_k = scale_ppm / dt
    steel = STEEL_PPM_PER_K * dt
    words = "warmer" if dt < 0 else "colder"
    note = (f"the reference was recorded {abs(dt):.2f} K {words} ({ref_c:.2f} C against {here_c:.2f} C, mean material "
            f"temperature): a steel leg ({STEEL_PPM_PER_K:g} ppm/K) shows a scale of {steel:+.1f} ppm against a "
            f"reference that much {words}; the scale found, {scale_ppm:+.1f} ppm, is {per_k:+.1f} ppm per K of the "
            "difference")
    if 0.5 * STEEL_PPM_PER_K <= per_k <= 2 * STEEL_PPM_PER_K:
        note += ": most likely the temperature difference, not a scale error (compare both normalised to 20 C)"
    return {"reference_temp_c": ref_c, "session_temp_c": here_c, "difference_k": dt, "scale_ppm_per_k": per_k,
            "steel_expansion_ppm": steel, "note": note}


def _diagnose_leg(leg: LegData, twin: Twin | None, s: DiagnosisSettings,
                  fixed: FixedReversal | None = None) -> tuple[dict, list[dict]]:
    """One leg's report and findings. `fixed`: the reversal from the leg's reversal probes
    (procedures/diagnosis/probe_reversal.py), taken out of the passes first and reported as the
    backlash finding instead of being selected among the effects."""
    raw_leg = leg
    if fixed is not None:  # the error holds -reversal/2 x direction (Backlash.columns): take it out
        leg = replace(leg, error_um=leg.error_um + 0.5 * fixed.reversal_um * leg.direction)
    ctx = prepare_leg(leg, twin, s)
    problem = ctx.problem
    can_cv = problem.folds is not None
    if twin is not None:
        gap = leg.error_um - ctx.fixed_um
    elif can_cv:
        gap = problem.heldout_residuals(())  # the twin predicts each cycle without having seen it
    else:
        x = problem.base
        gap = problem.y - x @ np.linalg.lstsq(x, problem.y, rcond=None)[0]
    rep = {"points": leg.n_points, "dropped_points": leg.dropped, "passes": leg.n_passes, "cycles": leg.n_cycles,
           "targets": leg.n_targets, "target_spacing_mm": leg.spacing_mm,
           "stroke_mm": list(leg.span_mm), "twin": ctx.twin_info,
           # the noise floor of station fit, computed the same way (pass offsets kept, no effect removed)
           "noise_floor_um": noise_floor(leg.x_mm, leg.direction, leg.run, leg.error_um).noise_floor_um}
    cannot = _cannot_conclude(leg, s, twin is not None)

    def where(scatter_um, explained_um=None):
        rep.update(breakdown(leg, gap, twin is not None, s.lead_mm, s.regions, s.threshold_um, scatter_um, explained_um,
                             s.motor_turn_mm))
        for p in rep.get("outlier_passes", []):
            cannot.append(f"run {p['run']} is {p['offset_um']:+.3g} um off the other passes: it dominates the pass "
                          "scatter against which effects are tested")
    findings: list[dict] = []
    cands: list[dict] = []
    applicable: list[Effect] = []
    for name in s.effects:
        e = EFFECTS[name]
        if fixed is not None and name == "backlash":
            cands.append({"effect": name, "status": "named", "p_value": fixed.p_value,
                          "reason": f"fixed by {fixed.pairs} reversal probe pairs before the other effects"})
            continue
        why = e.applicable(leg, twin is not None)
        guard = getattr(twin, "effect_guard", None)  # a fleet twin: a scale only where the features support it
        if why is None and guard is not None:
            why = guard(leg.leg, name)
        if why is None and not can_cv:
            why = "needs at least two cycles to score on held-out passes"
        if why is None:
            applicable.append(e)
        else:
            cands.append({"effect": name, "status": "not applicable", "reason": why})
    bonf = {"cyclic": EFFECTS["cyclic"].independent_frequencies(leg)} if isinstance(EFFECTS["cyclic"], Cyclic) else {}
    if not can_cv:
        fit = problem.full_fit((), bonf)
        rep["repeat_scatter_after_effects_um"] = repeatability_um(leg, fit.resid_um, outlier_mask(leg, gap, s.threshold_um))
        rep["repeat_scatter_after_effects_note"] = ("scatter of repeat passes at the same target and direction about the "
                                                    "twin (one cycle only: rough)")
        where(None)
        rep["combined"] = None
        rep["combined_note"] = "no held-out passes"
        rep["candidates"] = cands
        rep["cannot_conclude"] = cannot
        return rep, findings
    # the variants compete in the forward selection (a reversal that changes with temperature may
    # not qualify as a constant one), then each named effect is kept plain or as its variant
    with_variants = applicable + [v for e in applicable for v in VARIANTS.get(e.name, ())
                                  if v.applicable(leg, twin is not None) is None
                                  and not hasattr(v, "parts")]  # stacked variants: chosen jointly (selection.py)

    alternatives: list[dict] = []

    def select(problem):
        # effects and their variants chosen as sets on held-out passes (issue 35): confounded
        # candidates (drift and thermal while a leg warms, the reversal's variants) are compared
        # jointly, and the close alternatives rejected are kept for the report
        chosen, log, alts = select_jointly(problem, with_variants, VARIANTS, s.threshold_um, s.alpha, bonf,
                                           twin is not None)
        alternatives[:] = alts
        return chosen, log

    chosen, log = select(problem)
    for _round in range(TWIN_REFITS):
        if twin is not None or not chosen:
            break
        # the twin's size was chosen with the effects still in the data, where they act as noise
        # and can hide fine position structure (e.g. the wobble): choose it again without them
        # and repeat the selection with that twin; again while the twin changes (a large effect
        # estimated with a coarse twin leaves a remainder that keeps the next twin coarse too)
        part = problem.effect_part_um(problem.full_fit(chosen, bonf))
        ctx2 = prepare_leg(leg, None, s, leg.error_um - part)
        if ctx2.twin_info.get("wavelengths_mm") == ctx.twin_info.get("wavelengths_mm"):
            break
        ctx, problem = ctx2, ctx2.problem
        ctx.twin_info["fitted_without"] = [_name(e) for e in chosen]
        rep["twin"] = ctx.twin_info
        chosen, log2 = select(problem)
        log += ["twin refitted without the effects: " f"{ctx.twin_info.get('sinusoids')} sinusoids"] + log2
        gap = problem.heldout_residuals(())
    baseline = problem.cv_rms(())
    final = problem.full_fit(chosen, bonf)
    outliers = outlier_mask(leg, gap, s.threshold_um)
    rep["repeat_scatter_after_effects_um"] = repeatability_um(leg, final.resid_um, outliers)
    rep["repeat_scatter_after_effects_note"] = (
        "scatter of repeat passes at the same target and direction, after the twin and the named effects (pass "
        "offsets included" + (f"; {int(outliers.sum())} outlier point(s) left out)" if outliers.any() else ")"))
    rep["unexplained"] = unexplained(leg, final.resid_um, rep["repeat_scatter_after_effects_um"], s.threshold_um,
                                     s.alpha, outliers, twin is None)
    if rep["unexplained"] is None:
        rep["unexplained_note"] = "nothing systematic above the repeat scatter is left after the twin and the named effects"
    rep["within_pass_scatter_after_effects_um"] = final.gls.sigma_e_um
    rep["pass_offset_scatter_after_effects_um"] = final.gls.sigma_u_um
    where(rep["repeat_scatter_after_effects_um"], problem.effect_part_um(final) if chosen else None)
    # before/after in the order the effects were chosen, each on top of the ones before it; two
    # effects that only help together (chosen as a pair) share their before/after
    steps, i = [], 0
    while i < len(chosen):
        j = i + 1
        if j < len(chosen) and problem.cv_rms(chosen[:j]) >= problem.cv_rms(chosen[:i]):
            j += 1
        steps.append((i, j))
        i = j
    for i, j in steps:
        before, after = problem.cv_rms(chosen[:i]), problem.cv_rms(chosen[:j])
        for e in chosen[i:j]:
            sl = final.slices[e.name]
            params, se = e.parameters(final.gls.coef[sl], final.gls.cov[sl, sl], final.specs.get(e.name), leg,
                                      final.resid_um)
            f, p, df2 = final.tests[e.name]
            base_e = getattr(e, "base", e)
            findings.append({
                "leg": leg.leg, "effect": base_e.name, "parameters": params, "uncertainty": se,
                "heldout_rms_before_um": before, "heldout_rms_after_um": after,
                "shrink_pct": 100.0 * (1 - after / before) if before > 0 else 0.0,
                "heldout_contribution_um": contribution_um(before, after),
                "added_to": [_name(c) for c in chosen[:i]],
                "added_with": [_name(c) for c in chosen[i:j] if c is not e],
                "heldout_rms_alone_after_um": problem.cv_rms((e,)),
                "p_value": p, "f_stat": f, "df_denominator": df2,
            })
            if base_e is not e:
                findings[-1]["variant"] = e.variant
                findings[-1]["variant_p_value"] = final.tests[e.name + "+"][1]
                findings[-1]["heldout_rms_plain_after_um"] = problem.cv_rms(
                    tuple(base_e if c is e else c for c in chosen[:j]))
            if e.name == "scale" and twin is not None:
                tied = scale_and_temperature(params["scale_ppm"], leg, twin)
                if tied:
                    findings[-1]["temperature_difference"] = tied
            if e.name == "cyclic":
                warn = sampling_warning(params["wavelength_mm"], leg.spacing_mm, float(np.ptp(leg.x_mm)), s.lead_mm,
                                        s.motor_turn_mm)
                if warn:
                    findings[-1]["sampling"] = warn
    after_all = problem.cv_rms(chosen)
    if fixed is not None:
        baseline = _with_fixed_reversal(fixed, raw_leg, leg, twin, s, ctx, problem, chosen, bonf, findings, baseline)
        next(c for c in cands if c["effect"] == "backlash")["heldout_contribution_um"] = \
            findings[0]["heldout_contribution_um"]
    rep["combined"] = {"effects": (["backlash"] if fixed is not None else []) + [_name(e) for e in chosen],
                       "heldout_rms_before_um": baseline,
                       "heldout_rms_after_um": after_all,
                       "shrink_pct": 100.0 * (1 - after_all / baseline) if baseline > 0 else 0.0}
    chosen_base = tuple(getattr(c, "base", c) for c in chosen)
    for e in applicable:
        if e in chosen_base:
            fnd = next(f for f in findings if f["effect"] == e.name)
            cands.append({"effect": e.name, "status": "named", "p_value": fnd["p_value"],
                          "heldout_contribution_um": fnd["heldout_contribution_um"]})
            continue
        ev = evaluate(problem, chosen, e, bonf)
        entry = {"effect": e.name, "p_value": ev.p_value, "heldout_contribution_um": ev.contribution_um}
        if ev.p_value >= s.alpha:
            entry["status"] = "not significant"
            entry["reason"] = f"p = {ev.p_value:.2g} against the scatter between passes (needs < {s.alpha:g})"
        elif ev.contribution_um <= s.threshold_um:
            entry["status"] = "below threshold"
            entry["reason"] = f"adds {ev.contribution_um:.3g} um on held-out passes (threshold {s.threshold_um:g} um)"
        else:
            entry["status"] = "dropped"
            entry["reason"] = "qualified alone but not together with the named effects"
        if chosen:
            alone = evaluate(problem, (), e, bonf)
            if alone.qualifies(s.threshold_um, s.alpha):
                entry["status"] = "explained by others"
                entry["reason"] = (f"alone it would explain {alone.contribution_um:.3g} um, but once "
                                   f"{', '.join(_name(c) for c in chosen)} {'is' if len(chosen) == 1 else 'are'} in it adds "
                                   f"only {ev.contribution_um:.3g} um: confounded, not named")
        cands.append(entry)
    order = {n: i for i, n in enumerate(s.effects)}
    rep["candidates"] = sorted(cands, key=lambda c: order[c["effect"]])
    rep["selection_log"] = log
    rep["alternatives"] = alternatives
    if alternatives:
        a = alternatives[0]
        rep["alternatives_note"] = (f"closest alternative rejected: {', '.join(a['effects']) or 'nothing'}, held-out "
                                    f"{a['heldout_rms_after_um']:.3f} um against {after_all:.3f} um ({a['reason']})")
    rep["cannot_conclude"] = cannot
    return rep, findings


def _with_fixed_reversal(fixed: FixedReversal, raw_leg: LegData, leg: LegData, twin: Twin | None,
                         s: DiagnosisSettings, ctx: LegContext, problem: LegProblem, chosen: list, bonf: dict,
                         findings: list[dict], baseline_um: float) -> float:
    """The probes' reversal as the first finding (its held-out effect: the twin alone on the raw
    passes against on the passes without it), the other findings on top of it, their
    uncertainties widened by what one standard error of the reversal moves them (a refit with the
    reversal that much larger, added in quadrature). Returns the held-out RMS before any effect."""
    if chosen:
        final = problem.full_fit(chosen, bonf)
        moved = replace(leg, error_um=leg.error_um + 0.5 * fixed.stderr_um * leg.direction)
        refit = LegProblem(moved, problem.base, ctx.fixed_um, problem.folds).full_fit(chosen, bonf)
        for e, f in zip(chosen, findings):  # one finding per chosen effect, in order
            sl = final.slices[e.name]
            again, _ = e.parameters(refit.gls.coef[sl], refit.gls.cov[sl, sl], refit.specs.get(e.name), leg,
                                    refit.resid_um)
            for k, se in f["uncertainty"].items():
                if k in again:
                    f["uncertainty"][k] = float(np.hypot(se, again[k] - f["parameters"][k]))
            f["added_to"] = ["backlash"] + f["added_to"]
    before = prepare_leg(raw_leg, twin, s).problem.cv_rms(())
    findings.insert(0, {
        "leg": leg.leg, "effect": "backlash", "parameters": {"reversal_um": fixed.reversal_um},
        "uncertainty": {"reversal_um": fixed.stderr_um}, "source": "reversal probes", "probe_pairs": fixed.pairs,
        "heldout_rms_before_um": before, "heldout_rms_after_um": baseline_um,
        "shrink_pct": 100.0 * (1 - baseline_um / before) if before > 0 else 0.0,
        "heldout_contribution_um": contribution_um(before, baseline_um), "added_to": [], "added_with": [],
        "heldout_rms_alone_after_um": baseline_um, "p_value": fixed.p_value,
        "f_stat": (fixed.reversal_um / fixed.stderr_um) ** 2, "df_denominator": fixed.pairs - 1,
    })
    return before


def _passes_only(points: np.ndarray) -> tuple[np.ndarray, int]:
    """`points` without an on-the-fly session's anchors and reversal probes (FLAG_ANCHOR,
    FLAG_PROBE: single readings at rest beside the passes; as passes of their own they would
    be taken for outliers, and their NaN speed would hide the passes' speeds), and how many
    were set aside."""
    names = points.dtype.names or ()
    if "flags" not in names or len(points) == 0:
        return points, 0
    beside = (np.asarray(points["flags"]).astype(np.int64) & (FLAG_ANCHOR | FLAG_PROBE)) != 0
    return (points[~beside], int(beside.sum())) if beside.any() else (points, 0)


def diagnose(points: np.ndarray, twin: Twin | None = None, settings: DiagnosisSettings | None = None,
             recording: dict | None = None, source: str = "the session") -> dict:
    """Diagnose every leg of a POINT_DTYPE array against `twin` (None: a position-only twin
    fitted on this recording). `recording` (e.g. path and sha256) is copied into the report.
    Raises InputError/SchemaError for unusable input."""
    with single_threaded_blas():
        return _diagnose(points, twin, settings or DiagnosisSettings(), recording, source)


def _diagnose(points, twin, s: DiagnosisSettings, recording, source) -> dict:
    probes = probe_points(points) if "backlash" in s.effects else probe_points(points[:0])
    points, set_aside = _passes_only(points)
    legs = split_legs(points, source)
    report: dict = {
        "format": FORMAT, "version": VERSION, "recording": recording or {},
        "twin": ({"kind": "fitted", "description": "position-only twin (trend + selected sinusoids; target means when "
                  "there are few targets) fitted on this recording's training passes"} if twin is None else {"kind": twin.kind, "description": twin.description}),
        "settings": asdict(s), "findings": [], "legs": {}, "notes": [],
    }
    if set_aside:
        report["notes"].append(f"{set_aside} on-the-fly anchor and reversal probe reading(s) set aside: readings at rest "
                               "beside the passes, which the fit uses to take the passes static (docs/onthefly.md), "
                               "not passes to compare")
    for n, leg in legs.items():
        fixed = None
        if len(probes) and leg.n_cycles >= 2:  # the reversal from the probes (probe_reversal.py)
            fixed = fixed_reversal(probes[probes["leg"] == n], leg, twin)
            if fixed is not None:
                report["notes"].append(fixed.note(n))
        rep, findings = _diagnose_leg(leg, twin, s, fixed)
        report["legs"][str(n)] = rep
        report["findings"].extend(findings)
    if not report["findings"]:
        report["notes"].append("no effect qualified on any leg")
    extra: list[str] = []
    out = finite_or_null(report, extra)
    out["notes"].extend(extra)
    return out


def finite_or_null(obj, notes: list[str], path: str = ""):
    """A JSON-able copy: numpy types to Python, non-finite numbers to None (noted in `notes`)."""
    if isinstance(obj, dict):
        return {str(k): finite_or_null(v, notes, f"{path}.{k}" if path else str(k)) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_or_null(v, notes, f"{path}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, np.ndarray):
        return finite_or_null(obj.tolist(), notes, path)
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        if not math.isfinite(v):
            notes.append(f"{path}: could not be computed (not a finite number)")
            return None
        return v
    return obj


def to_json(report: dict) -> str:
    """The report as JSON text (strict: no NaN/Infinity)."""
    return json.dumps(report, indent=1, allow_nan=False)
