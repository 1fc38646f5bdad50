"""Conformance decisions of ISO 230-2 values against tolerances, by the ISO 14253-1 rule with the
expanded uncertainty U (k = 2) of each value (procedures.metrology.uncertainty). docs/decisions.md.

The values decided (E, A, B, R, M) are magnitudes >= 0 with one-sided upper limits L (um):

    value + U <= L          conforms          (the whole interval [value - U, value + U] is inside)
    value - U >  L          does not conform  (the whole interval is outside)
    otherwise               cannot decide     (the interval straddles L; the reason names the
                                               contribution that dominates U, from the budget)

A leg without a leg type, or a type without tolerances, gets "no tolerance stated" and no
decision; a value the standard could not compute gets "not computed". The comparisons carry a
slack of SLACK_UM for float rounding only (4.9 + 1.1 is 6.000000000000001 in binary).

Tolerances come from the station config, one section per leg type (parse_tolerances):

    [tolerances.HX300]            # limits that hold as found and as left
    E_um = 6.0
    B_um = 2.0
    [tolerances.HX300.as_left]    # tighter limits after compensation (override, per value)
    E_um = 3.0
    [tolerances.HX300.as_found]   # (optional) as-found-only limits
    R_um = 4.0

A section may name the specification its limits come from (`spec = "HX-SPEC-300"`,
`spec_revision = "C"`): a certificate states the specification by that identifier and revision
rather than by the config file it was read from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

from procedures.vocabulary import InputError

DECIDED = ("E", "A", "B", "R", "M")  # bidirectional ISO 230-2 values with a tolerance
STAGES = ("as_found", "as_left")
CONFORMS = "conforms"
NOT_CONFORM = "does not conform"
UNDECIDED = "cannot decide"
NO_TOLERANCE = "no tolerance stated"
NOT_COMPUTED = "not computed"
SLACK_UM = 1e-9
SPEC_KEYS = ("spec", "spec_revision")  # [tolerances.TYPE] text keys: the specification the limits come from
RULE = ("ISO 14253-1: conforms when value + U <= limit, does not conform when value - U > limit, "
        "otherwise cannot decide (U expanded, k = 2)")


@dataclass(frozen=True)
class Tolerance:
    """Upper limits (um) of one leg type, by stage ("as_found" / "as_left") and value name."""

    leg_type: str
    as_found: dict[str, float] = field(default_factory=dict)
    as_left: dict[str, float] = field(default_factory=dict)
    source: str = ""  # where it was read: "FILE [tolerances.TYPE]"
    spec: str = ""  # the specification's identifier ("" = not stated), e.g. a drawing or standard number
    spec_revision: str = ""

    @property
    def specification(self) -> str:
        """The specification as a certificate names it: "ID revision R", "" when none is stated."""
        if not self.spec:
            return ""
        return f"{self.spec} revision {self.spec_revision}" if self.spec_revision else f"{self.spec} (revision not stated)"

    def limits(self, stage: str) -> dict[str, float]:
        if stage not in STAGES:
            raise ValueError(f"stage {stage!r}: one of {STAGES}")
        return dict(self.as_found if stage == "as_found" else self.as_left)

    def to_json(self) -> dict[str, Any]:
        return {"leg_type": self.leg_type, "as_found_um": dict(self.as_found), "as_left_um": dict(self.as_left),
                "source": self.source, "spec": self.spec, "spec_revision": self.spec_revision}


def _limit(where: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{where} {key}: expected a number of micrometres, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v <= 0:
        raise InputError(f"{where} {key} = {value!r}: must be a finite number > 0 (an upper limit in um)")
    return v


def _keys(where: str, table: Any) -> dict[str, float]:
    if not isinstance(table, dict):
        raise InputError(f"{where} must be a table of keys")
    out = {}
    for key, value in table.items():
        if key in SPEC_KEYS:
            continue  # text, read by parse_tolerances
        name = key[:-3] if key.endswith("_um") else None
        if name not in DECIDED:
            raise InputError(f"{where} {key}: unknown key (known: {', '.join(n + '_um' for n in DECIDED)}, "
                             "and the sub-tables as_found / as_left)")
        out[name] = _limit(where, key, value)
    return out


def parse_tolerances(table: Any, path: str) -> dict[str, Tolerance]:
    """leg type -> Tolerance from a config's `[tolerances]` table; InputError naming the file,
    section and key of anything wrong."""
    if not isinstance(table, dict):
        raise InputError(f"{path}: [tolerances] must hold one section per leg type, e.g. [tolerances.HX300]")
    out = {}
    for leg_type, body in table.items():
        where = f"{path}: [tolerances.{leg_type}]"
        if not isinstance(body, dict):
            raise InputError(f"{where}: expected a section of limits (E_um = 6.0, ...), got {body!r}")
        both = _keys(where, {k: v for k, v in body.items() if k not in STAGES})
        stages = {s: {**both, **_keys(f"{path}: [tolerances.{leg_type}.{s}]", body.get(s, {}))} for s in STAGES}
        if not stages["as_found"] and not stages["as_left"]:
            raise InputError(f"{where}: states no limit; give at least one of "
                             f"{', '.join(n + '_um' for n in DECIDED)}")
        spec = {}
        for key in SPEC_KEYS:
            value = body.get(key, "")
            if not isinstance(value, str):
                raise InputError(f"{where} {key}: expected text (the specification's identifier or revision), "
                                 f"got {value!r}")
            spec[key] = value.strip()
        if spec["spec_revision"] and not spec["spec"]:
            raise InputError(f"{where} spec_revision = {spec['spec_revision']!r} without spec: name the specification "
                             "(spec = \"...\") whose revision it is")
        out[str(leg_type)] = Tolerance(str(leg_type), stages["as_found"], stages["as_left"],
                                       f"{path} [tolerances.{leg_type}]", **spec)
    return out


def tolerances_from_json(d: Mapping[str, Any] | None) -> dict[str, Tolerance]:
    """The inverse of {type: Tolerance.to_json()} (a session's recorded config)."""
    out = {}
    for leg_type, t in (d or {}).items():
        if isinstance(t, dict):
            out[str(leg_type)] = Tolerance(str(leg_type), {k: float(v) for k, v in (t.get("as_found_um") or {}).items()},
                                           {k: float(v) for k, v in (t.get("as_left_um") or {}).items()},
                                           str(t.get("source", "")), str(t.get("spec") or ""),
                                           str(t.get("spec_revision") or ""))
    return out


@dataclass(frozen=True)
class Decision:
    """One value against one limit: `outcome` is CONFORMS, NOT_CONFORM, UNDECIDED, NO_TOLERANCE
    or NOT_COMPUTED; `reason` says why in a sentence."""

    name: str
    value_um: float | None
    U_um: float | None
    limit_um: float | None
    outcome: str
    reason: str
    dominant: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {"value_um": self.value_um, "U_um": self.U_um, "limit_um": self.limit_um, "outcome": self.outcome,
                "reason": self.reason, "dominant": self.dominant}


def dominant_source(contributions: Iterable[Mapping[str, Any]]) -> tuple[str, float] | None:
    """The source whose contributions make up most of u_c^2 and its share (0..1); the many
    target means and estimators of one source ("repeatability") are summed in quadrature."""
    var: dict[str, float] = {}
    for c in contributions:
        var[str(c["source"])] = var.get(str(c["source"]), 0.0) + float(c["u_um"]) ** 2
    total = sum(var.values())
    if total <= 0:
        return None
    src = max(var, key=var.get)
    return src, var[src] / total


def decide(name: str, value_um: float | None, U_um: float | None, limit_um: float | None,
           contributions: Iterable[Mapping[str, Any]] = ()) -> Decision:
    """The ISO 14253-1 decision of `value_um` +/- `U_um` against the upper limit `limit_um`
    (module docstring); `contributions` (the value's budget rows: source, u_um) name what
    dominates U when no decision can be made."""
    if limit_um is None:
        return Decision(name, value_um, U_um, None, NO_TOLERANCE, f"no tolerance stated for {name}")
    if value_um is None:
        return Decision(name, None, U_um, limit_um, NOT_COMPUTED, f"{name} was not computed: no decision")
    if U_um is None:
        return Decision(name, value_um, None, limit_um, UNDECIDED,
                        f"{name} has no computed uncertainty: ISO 14253-1 cannot decide without U")
    dom = dominant_source(contributions)
    dom_text = f"{dom[0]} ({100 * dom[1]:.0f} % of u^2)" if dom else None
    if value_um + U_um <= limit_um + SLACK_UM:
        return Decision(name, value_um, U_um, limit_um, CONFORMS,
                        f"{value_um:.3f} + {U_um:.3f} = {value_um + U_um:.3f} um <= {limit_um:g} um", dom_text)
    if value_um - U_um > limit_um + SLACK_UM:
        return Decision(name, value_um, U_um, limit_um, NOT_CONFORM,
                        f"{value_um:.3f} - {U_um:.3f} = {value_um - U_um:.3f} um > {limit_um:g} um", dom_text)
    why = (f"{value_um - U_um:.3f} .. {value_um + U_um:.3f} um straddles the limit {limit_um:g} um")
    if U_um > limit_um:
        why += f"; U = {U_um:.3f} um exceeds the tolerance itself, so no value can be proven to conform"
    if dom_text:
        why += f"; U is dominated by {dom_text}"
    return Decision(name, value_um, U_um, limit_um, UNDECIDED, why, dom_text)


def overall(decisions: Iterable[Decision]) -> str:
    """One verdict for a leg: does not conform if any value does not, conforms when every
    value with a limit conforms, no tolerance stated when none has a limit, else cannot decide."""
    ds = [d for d in decisions if d.outcome != NO_TOLERANCE]
    if not ds:
        return NO_TOLERANCE
    if any(d.outcome == NOT_CONFORM for d in ds):
        return NOT_CONFORM
    if all(d.outcome == CONFORMS for d in ds):
        return CONFORMS
    return UNDECIDED


def stage_of(plan_kind: str | None, stage: str | None = None) -> str:
    """The stage a session is decided at: "as_left" for a verification sweep (plan kind
    "verification", after compensation) or a session whose plan states stage "verification"
    (an import given its stage), else "as_found"."""
    return "as_left" if plan_kind == "verification" or stage == "verification" else "as_found"


def decide_leg(leg_values: Mapping[str, Any], budget_values: Mapping[str, Any], leg_type: str | None,
               tolerances: Mapping[str, Tolerance], stage: str) -> dict[str, Any]:
    """The decisions of one leg of an ISO 230-2 report (procedures.reporting.iso230_report.build's
    legs[leg]["values"] and ["budget"]["values"]) at `stage`, as a JSON-able dict:
    {stage, leg_type, tolerance_source, overall, reason, values: {name: Decision.to_json()}}."""
    tol = tolerances.get(leg_type) if leg_type else None
    out: dict[str, Any] = {"stage": stage, "leg_type": leg_type or None, "rule": RULE,
                           "tolerance_source": tol.source if tol else None,
                           "specification": (tol.specification or None) if tol else None}
    if tol is None:
        out.update(overall=NO_TOLERANCE, values={},
                   reason=("the leg has no leg type recorded ([legs.N] leg_type)" if not leg_type else
                           f"no [tolerances.{leg_type}] in the station config"))
        return out
    limits = tol.limits(stage)
    ds = []
    for name in DECIDED:
        v = leg_values.get(name) or {}
        ds.append(decide(name, v.get("value_um"), v.get("U_um"), limits.get(name),
                         (budget_values.get(name) or {}).get("contributions") or ()))
    out["values"] = {d.name: d.to_json() for d in ds if d.outcome != NO_TOLERANCE}
    out["overall"] = overall(ds)
    out["reason"] = "; ".join(f"{d.name}: {d.outcome}" for d in ds if d.outcome != NO_TOLERANCE) or \
        f"[tolerances.{leg_type}] states no {stage.replace('_', '-')} limit"
    return out


def decide_report(iso: Mapping[str, Any], tolerances: Mapping[str, Tolerance], stage: str) -> dict[str, Any]:
    """leg -> decide_leg for every leg of an ISO 230-2 report dict, the leg type from its
    identification (the session identity)."""
    ident = (iso.get("identification") or {}).get("leg_identity") or {}
    out = {}
    for leg, L in (iso.get("legs") or {}).items():
        lt = (ident.get(leg) or {}).get("leg_type")
        lt = None if lt in (None, "", "not stated", "not recorded") else lt
        out[leg] = decide_leg(L["values"], (L.get("budget") or {}).get("values") or {}, lt, tolerances, stage)
    return out


def decision_lines(decisions: Mapping[str, Any]) -> list[str]:
    """What the command line prints: one line per leg, one per value decided."""
    lines = []
    for leg, d in decisions.items():
        stage = d["stage"].replace("_", "-")
        head = f"leg {leg} ({d['leg_type'] or 'no leg type'}), {stage}: {d['overall'].upper()}"
        if d["overall"] == NO_TOLERANCE:
            lines.append(f"{head}: {d['reason']}")
            continue
        lines.append(f"{head} ({d['tolerance_source']})")
        for name, v in d["values"].items():
            lines.append(f"  {name}: {v['outcome']}: {v['reason']}")
    return lines


def decision_summary(decisions: Mapping[str, Any]) -> str:
    """One line for a screen: each leg's verdict and, when undecided or failing, which value and why
    in a few words; "" when no leg has a tolerance (nothing to say)."""
    parts = []
    for leg, d in decisions.items():
        if d["overall"] == NO_TOLERANCE:
            continue
        text = f"leg {leg} {d['overall'].upper()}"
        bad = [(n, v) for n, v in d["values"].items() if v["outcome"] in (NOT_CONFORM, UNDECIDED)]
        if bad:
            n, v = bad[0]
            text += f" ({n} {v['value_um']:.2f} ± {v['U_um']:.2f} vs {v['limit_um']:g} µm" + (
                f"; U: {v['dominant'].split(' (')[0]}" if v["outcome"] == UNDECIDED and v.get("dominant") else "") + ")"
        parts.append(text)
    return ", ".join(parts)

