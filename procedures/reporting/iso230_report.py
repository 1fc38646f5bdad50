"""The ISO 230-2 test report of a session: what the standard's report states, with the expanded
uncertainty (k = 2) of every value (procedures.metrology.uncertainty). Part of `station report`
(procedures.reporting.session_report.make_report writes it beside the other report files); docs/uncertainty.md.

Files, written atomically (procedures.io.atomic_outputs) into the report folder:
- iso230-2.json   every figure: identification, environment, materials and NDE, test parameters,
                  compensation state, per leg and value {value_um, U_um} and the full budget,
                  U of each target's mean deviation (what a compensation table entry is made of)
- iso230-2.md     the same for reading
- iso230-2.png    the standard's graph: mean deviation up and down against the target, +/-2s bands
- iso230-2.pdf    the report as a document (fpdf2), the graph embedded

Errors are measured minus target (um); the ISO values are evaluated on the error normalised to
the reference temperature (procedures.metrology.thermal) when the session recorded material
temperatures, else on the raw error, and the report says which.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from procedures.reporting import decision, iso230
from procedures.io.atomic_outputs import atomic_path, write_bytes_atomic
from procedures.metrology.uncertainty import K_COVERAGE, UncertaintyInputs, leg_budget, table_budget
from procedures.io.recording.identity import SessionIdentity, calibration_warnings, identity_from_json, instrument_identity

VALUE_ORDER = ("E", "E_up", "E_down", "M", "A", "A_up", "A_down", "B", "B_mean", "R", "R_up", "R_down")
MEANING = {"E": "systematic positional deviation, bidirectional", "E_up": "systematic positional deviation, up",
           "E_down": "systematic positional deviation, down", "M": "range of mean bidirectional deviation",
           "A": "accuracy, bidirectional", "A_up": "accuracy, up", "A_down": "accuracy, down",
           "B": "reversal value (max |B_i|)", "B_mean": "mean reversal value", "R": "repeatability, bidirectional",
           "R_up": "repeatability, up", "R_down": "repeatability, down"}
FILES = ("iso230-2.json", "iso230-2.md", "iso230-2.png", "iso230-2.pdf")


def _range(v: np.ndarray) -> list[float] | None:
    v = np.asarray(v, dtype=float)
    v = v[np.isfinite(v)]
    return [float(v.min()), float(v.max())] if v.size else None


def normalised_points(points: np.ndarray, station_config: dict) -> tuple[np.ndarray, dict[str, Any]]:
    """The points whose error_um is normalised to the reference temperature, and what was done."""
    try:
        from procedures.metrology.thermal import normalise_session
    except ImportError:  # the normalisation is not part of this build
        return points, {"basis": "raw", "statement": "raw error (no normalisation to 20 degC available)"}
    norm = normalise_session(points, station_config)
    info = norm.to_json()
    if norm.any:
        legs = ", ".join(str(leg) for leg in norm.normalised)
        info["basis"] = "normalised"
        info["statement"] = (f"Deviations normalised to {norm.reference_temp_c:g} degC material temperature by the "
                             f"nominal differential expansion (NDE) correction, legs {legs}; materials from "
                             f"{norm.source}. The session keeps the raw error.")
        if norm.raw:
            info["statement"] += " Raw error on " + "; ".join(f"leg {k}: {v}" for k, v in sorted(norm.raw.items())) + "."
    else:
        info["basis"] = "raw"
        why = "; ".join(f"leg {k}: {v}" for k, v in sorted(norm.raw.items()))
        info["statement"] = (f"Deviations NOT normalised to {norm.reference_temp_c:g} degC ({why}): the NDE "
                             "correction could not be applied; the values hold at the recorded temperature.")
    return norm.points, info


def _test_parameters(plan: dict, legs: list[int], iso: dict) -> dict[str, Any]:
    targets = plan.get("targets_mm")
    if not targets:  # an import: the targets are what the data holds
        first = iso[legs[0]] if legs else None
        targets = [t.target_mm for t in first.up] if first else []
    feed = plan.get("feed_mm_s") or plan.get("velocity_mm_s")
    speeds = plan.get("speeds_mm_s") or []
    return {
        "plan": plan.get("kind", "n/a"),
        "targets_mm": [float(t) for t in targets],
        "n_targets": len(targets),
        "cycles": plan.get("cycles", min((r.n_cycles for r in iso.values()), default=0)),
        "feed_mm_s": feed,
        "speeds_mm_s": list(speeds),
        "feed_statement": (f"{feed:g} mm/s" if feed else
                           "on-the-fly capture at " + ", ".join(f"{v:g}" for v in speeds) + " mm/s" if speeds else
                           "the drive's profile velocity (not recorded in the session; the default drive profile sets "
                           "10 mm/s)"),
        "dwell_s": plan.get("dwell_s"),
        "averaging_s": plan.get("averaging_s"),
        "overrun_mm": plan.get("overrun_mm"),
        "approach": _approach(plan),
    }


def _approach(plan: dict) -> str:
    """The approach in words, with the overrun the plan recorded (never the key's name)."""
    if plan.get("kind") == "import":
        return "as recorded by the other software (imported)"
    over = plan.get("overrun_mm")
    start = (f"{over:g} mm beyond its first target" if isinstance(over, (int, float)) and not isinstance(over, bool)
             else "beyond its first target (overrun not recorded in the session)")
    return (f"linear cycle, bidirectional: every pass starts {start}, each target approached in the pass's "
            "direction (ISO 230-2 standard test cycle)")


def _air_compensation(record: Any) -> str:
    """What the session recorded about the instrument's air compensation (procedures.acquisition.sweep's
    laser_compensation_record: JSON text, or a sentence), as one line."""
    if not record:
        return "not recorded"
    try:
        d = json.loads(record)
    except (TypeError, ValueError):
        return str(record)
    if not isinstance(d, dict):
        return str(d)
    # the instrument's record in words: a sensor value left empty is read live at every reading
    # (mode AUTO), not missing
    known = (("mode", "mode {}", ""), ("equation", "equation {}", ""), ("wavelength_nm", "vacuum wavelength {} nm", ""),
             ("air_temp_c", "air temperature {} degC", "air temperature"), ("air_pressure_hpa", "pressure {} hPa", "pressure"),
             ("humidity_pct", "humidity {} %RH", "humidity"), ("co2_ppm", "CO2 {} ppm", "CO2"),
             ("dead_path_mm", "dead path {} mm", "dead path"))
    said, live = [], []
    for key, text, live_name in known:
        if key in d:
            if d[key] is None:
                if live_name:
                    live.append(live_name)
            else:
                said.append(text.format(d[key]))
    said += [f"{k} {v}" for k, v in sorted(d.items()) if k not in {k for k, _, _ in known}]
    if live:
        said.append(f"{', '.join(live)} from the instrument's sensors at each reading")
    return ", ".join(said)


def _session_day(attrs: dict) -> _dt.date | None:
    try:
        return _dt.datetime.fromisoformat(str(attrs.get("started_utc") or "")).date()
    except ValueError:
        return None


def _identity_block(identity: SessionIdentity, attrs: dict, metrology: dict, legs: list[int]) -> dict[str, Any]:
    """Station, leg serials and the laser's calibration state (due date, traceable, warnings) for
    the day the session started; a session without identity (schema 1.0) falls back on its
    recorded [metrology] and says what is not recorded."""
    ins = identity.instrument
    if not identity.recorded:
        ins = instrument_identity(metrology.get("model"), metrology.get("serial"), metrology.get("calibration_due"),
                                  metrology.get("calibration_date"), _session_day(attrs))
    elif ins.calibration_due:  # traceability is judged on the day of the measurement, not of the report
        ins = instrument_identity(ins.model, ins.serial, ins.calibration_due, ins.calibrated_on, _session_day(attrs))
    warnings = calibration_warnings(ins, _session_day(attrs))
    return {
        "station": {"id": identity.station.id or "not recorded", "host": identity.station.host or "not recorded"},
        "software_version": identity.software_version or attrs.get("software_version", "") or "not recorded",
        "leg_identity": {str(leg): {"serial": identity.leg(leg).serial or "not recorded",
                                    "part_number": identity.leg(leg).part_number or "not stated",
                                    "leg_type": identity.leg(leg).leg_type or "not stated",
                                    "screw_lot": identity.leg(leg).screw_lot or "not stated"} for leg in legs},
        "calibration_due": ins.calibration_due or "not stated", "traceable": ins.traceable,
        "calibration_warnings": warnings,
    }


def _identification(attrs: dict, devices: dict, metrology: dict, source: dict, legs: list[int],
                    identity: SessionIdentity | None = None) -> dict[str, Any]:
    used = UncertaintyInputs.from_dicts(metrology, {})
    said = "" if metrology else " (station default: the session recorded no [metrology])"
    who = _identity_block(identity or SessionIdentity.unknown(), attrs, metrology, legs)
    return {
        "station": who["station"], "software_version": who["software_version"],
        "leg_identity": who["leg_identity"],
        "session_file": source.get("path", ""), "session_sha256": source.get("sha256", ""),
        "session_id": attrs.get("session_id", ""), "operator": attrs.get("operator", ""),
        "rig": attrs.get("rig", ""), "started_utc": attrs.get("started_utc", ""), "ended_utc": attrs.get("ended_utc", ""),
        "outcome": attrs.get("outcome", "") or "incomplete",
        "legs": {str(leg): devices.get(f"leg{leg}", "not recorded") for leg in legs},
        "instrument": {
            "reported_identity": devices.get("interferometer", "not recorded"),
            "model": metrology.get("model") or "not stated",
            "serial": metrology.get("serial") or "not stated",
            "calibration_date": metrology.get("calibration_date") or "not stated",
            "calibration_due": who["calibration_due"], "traceable": who["traceable"],
            "calibration_warnings": who["calibration_warnings"],
            "wavelength_nm": used.wavelength_nm,
            "laser_accuracy_ppm_k2": used.laser_accuracy_ppm,
            "resolution_nm": used.laser_resolution_nm,
            "settings_source": said.strip(" ()") or "the session's recorded [metrology]",
        },
        "air_compensation": _air_compensation(devices.get("laser_air_compensation") or devices.get("air_compensation")),
    }


def build(points: np.ndarray, *, plan: dict, devices: dict, station_config: dict, attrs: dict,
          source: dict, raw: bool = False, identity: dict | None = None,
          tolerances: dict | None = None, stage: str | None = None) -> dict[str, Any]:
    """The ISO 230-2 report's content as a JSON-able dict (module docstring); `raw`: on the raw
    error (`station report --raw`, or a model fitted to it), not normalised to 20 degC;
    `identity`: the session's /meta/identity (procedures.io.recording.identity), {} or None when it
    has none; `tolerances`: {leg type: procedures.reporting.decision.Tolerance.to_json()} to decide by
    (None or {}: the ones the session's config recorded); `stage` "as_found" / "as_left" (None:
    as left for a session whose plan kind is "verification", else as found)."""
    if raw:
        pts, basis = points, {"basis": "raw", "normalised": False,
                              "statement": "Deviations NOT normalised to 20 degC (raw error asked for: --raw, or a model "
                                           "fitted to the raw error): the values hold at the recorded temperature."}
    else:
        pts, basis = normalised_points(points, station_config or {})
    iso = iso230.evaluate(pts)
    legs = sorted(iso)
    metrology = (station_config or {}).get("metrology") or {}
    out: dict[str, Any] = {
        "standard": "ISO 230-2", "uncertainty": f"ISO/TR 230-9 style budget, GUM, expanded uncertainty U with k = {K_COVERAGE:g}",
        "units": "um", "error_basis": basis,
        "identification": _identification(attrs or {}, devices or {}, metrology, source, legs,
                                          identity_from_json(identity) if identity else None),
        "test_parameters": _test_parameters(plan or {}, legs, iso),
        "legs": {},
    }
    out["warnings"] = list(out["identification"]["instrument"]["calibration_warnings"])
    for leg in legs:
        r = iso[leg]
        inputs = UncertaintyInputs.from_record(station_config or {}, leg)
        budget = leg_budget(r, pts, inputs)
        lp = points[points["leg"] == leg]
        env = {"air_temp_c": _range(lp["air_temp_c"]), "material_temp_c": _range(lp["material_temp_c"]),
               "pressure_hpa": _range(lp["air_pressure_hpa"]), "humidity_pct": _range(lp["humidity_pct"])}
        values = {}
        for name in VALUE_ORDER:
            v = r.values.get(name)
            b = budget.values.get(name)
            values[name] = {"value_um": v, "U_um": b.U_um if (b is not None and v is not None) else None,
                            "meaning": MEANING[name]}
            if v is None:
                values[name]["not_computed"] = r.reasons.get(name, "")
            elif b is not None:
                dom = b.dominant()
                values[name]["dominant"] = dom.source if dom else None
        targets = []
        for word, stats, d in (("up", r.up, 1), ("down", r.down, -1)):
            for t in stats:
                sel = lp[(lp["direction"] == d) & (np.abs(lp["target_mm"] - t.target_mm) <= iso230.TARGET_TOLERANCE_MM)]
                mt = sel["material_temp_c"][np.isfinite(sel["material_temp_c"])]
                dt = float(mt.mean()) - inputs.reference_temp_c if mt.size else 0.0
                u = table_budget([t.target_mm], t.s_um or 0.0, t.n, inputs, dt, budget.sensitivities,
                                 float(np.ptp([s.target_mm for s in r.up + r.down])))[0]
                targets.append({"direction": word, "target_mm": t.target_mm, "n": t.n, "mean_um": t.mean_um,
                                "s_um": t.s_um, "U_um": u["U_um"]})
        out["legs"][str(leg)] = {
            "compensation": devices.get(f"leg{leg}_compensation", "not recorded") if devices else "not recorded",
            "environment": env,
            "material": {"expansion_um_m_k": inputs.expansion_um_m_k, "expansion_u_um_m_k": inputs.expansion_u_um_m_k,
                         "fixed_point_mm": inputs.fixed_point_mm, "reference_temp_c": inputs.reference_temp_c},
            "n_targets": r.n_targets, "n_cycles": r.n_cycles, "n_points": r.n_points,
            "values": values, "notes": list(r.notes) + list(budget.notes),
            "targets": targets, "budget": budget.to_json(),
        }
    tol = decision.tolerances_from_json(tolerances or (station_config or {}).get("tolerances"))
    stage = stage or decision.stage_of((plan or {}).get("kind"), (plan or {}).get("stage"))
    out["decisions"] = {"stage": stage, "rule": decision.RULE, "legs": decision.decide_report(out, tol, stage)}
    return json_safe(out)


def json_safe(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [json_safe(x) for x in v]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


# -- text ---------------------------------------------------------------------------------------------

def _f(v: Any, spec: str = ".3f") -> str:
    return "n/a" if v is None else format(v, spec)


def _rng(r: list[float] | None, spec: str = ".2f") -> str:
    return "not recorded" if not r else f"{r[0]:{spec}} .. {r[1]:{spec}}"


def sections(d: dict[str, Any]) -> list[tuple[str, list[str], list[list[str]] | None]]:
    """The report as (heading, paragraphs, table rows or None); Markdown and PDF render these."""
    ident = d["identification"]
    ins = ident["instrument"]
    tp = d["test_parameters"]
    out: list = []
    trace = ("in calibration on the day of the test (traceable)" if ins.get("traceable")
             else "NOT traceable")
    out.append(("Identification", [f"WARNING: {w}." for w in d.get("warnings", [])] + [
        f"Station: {ident['station']['id']} (host {ident['station']['host']}), software {ident['software_version']}.",
        f"Session: {ident['session_file'] or 'n/a'} (sha256 {(ident['session_sha256'] or 'n/a')[:16]}), id "
        f"{ident['session_id'] or 'n/a'}, {ident['rig'] or 'n/a'} rig, operator {ident['operator'] or 'n/a'}, "
        f"{ident['started_utc'] or 'n/a'} to {ident['ended_utc'] or 'n/a'}, outcome {ident['outcome']}.",
        f"Instrument: {ins['model']}, serial {ins['serial']}, calibrated {ins['calibration_date']}, calibration due "
        f"{ins['calibration_due']}: {trace}; reports itself as "
        f"'{ins['reported_identity']}'; vacuum wavelength {_f(ins['wavelength_nm'], '.3f')} nm, stated accuracy "
        f"{_f(ins['laser_accuracy_ppm_k2'], 'g')} ppm (k = 2), resolution {_f(ins['resolution_nm'], 'g')} nm "
        f"(settings: {ins['settings_source']}).",
        f"Air compensation: {ident['air_compensation']}.",
    ], [["leg", "serial", "part number", "type", "screw lot", "drive"]]
        + [[k, li["serial"], li["part_number"], li["leg_type"], li["screw_lot"], ident["legs"][k]]
           for k, li in ident["leg_identity"].items()]))
    env_rows = [["leg", "air temperature (degC)", "material temperature (degC)", "pressure (hPa)", "humidity (%RH)"]]
    for leg, L in d["legs"].items():
        e = L["environment"]
        env_rows.append([leg, _rng(e["air_temp_c"]), _rng(e["material_temp_c"]), _rng(e["pressure_hpa"]),
                         _rng(e["humidity_pct"], ".1f")])
    out.append(("Environment (min .. max during the test)", [], env_rows))
    mat_rows = [["leg", "expansion coefficient (um/m/K)", "fixed point (mm)", "reference (degC)"]]
    for leg, L in d["legs"].items():
        m = L["material"]
        mat_rows.append([leg, f"{m['expansion_um_m_k']:g} +/- {m['expansion_u_um_m_k']:g} (u, k = 1)",
                         f"{m['fixed_point_mm']:g}", f"{m['reference_temp_c']:g}"])
    out.append(("Expansion coefficient and NDE", [d["error_basis"]["statement"]], mat_rows))
    targets = ", ".join(f"{t:g}" for t in tp["targets_mm"][:15]) + (" ..." if len(tp["targets_mm"]) > 15 else "")
    out.append(("Test parameters", [
        f"Plan {tp['plan']}: {tp['n_targets']} targets (mm): {targets}.",
        f"Cycles: {tp['cycles']}; feed: {tp['feed_statement']}; dwell {_f(tp['dwell_s'], 'g')} s, averaging "
        f"{_f(tp['averaging_s'], 'g')} s; overrun {_f(tp['overrun_mm'], 'g')} mm.",
        f"Approach: {tp['approach']}.",
    ], None))
    out.append(("Compensation state at the start of the test",
                [f"Leg {leg}: {L['compensation']}." for leg, L in d["legs"].items()], None))
    for leg, L in d["legs"].items():
        rows = [["value", "um", f"U (k = {K_COVERAGE:g}), um", "dominant contribution", "meaning"]]
        for name, v in L["values"].items():
            rows.append([name, _f(v["value_um"]), _f(v["U_um"]), v.get("dominant") or "-",
                         v["meaning"] if v["value_um"] is not None else f"not computed: {v.get('not_computed', '')}"])
        paras = [f"{L['n_targets']} targets, {L['n_cycles']} approaches per target and direction (fewest), "
                 f"{L['n_points']} points; error {d['error_basis']['basis']}."]
        paras += [f"Note: {n}" for n in L["notes"]]
        out.append((f"Leg {leg}: ISO 230-2 values with expanded uncertainty", paras, rows))
        dec = ((d.get("decisions") or {}).get("legs") or {}).get(leg)
        if dec:
            out.append(decision_section(leg, dec))
        b = L["budget"]["values"]
        for name in ("E", "A", "B"):
            if name not in b:
                continue
            vb = b[name]
            brows = [["source", "input quantity", "u(input)", "unit", "sensitivity (um/unit)", "contribution (um)"]]
            for c in _grouped(vb["contributions"]):
                brows.append([c["source"], c["quantity"], c["u_input"], c["unit"], c["sensitivity"], f"{c['u_um']:.4f}"])
            brows.append(["combined", "", "", "", "u_c", f"{vb['u_um']:.4f}"])
            out.append((f"Leg {leg}: budget of {name} = {vb['value_um']:.3f} um, U = {vb['U_um']:.3f} um",
                        [vb["formed"]], brows))
    out.append(("How U is formed", [
        "Every contribution is a standard uncertainty times its sensitivity coefficient; U = 2 u_c (GUM, k = 2). "
        "Length-proportional terms (laser, air sensors through the refractive index, misalignment, material "
        "temperature and expansion coefficient) are one value for the whole test: fully correlated between targets, "
        "they act through the distance between the targets that set a value, and cancel in B. Target means and "
        "estimators are independent between targets. Max and min are taken over all targets (Clark 1961), so a "
        "near tie does not inflate U. Details: docs/uncertainty.md.",
    ], None))
    return out


def decision_section(leg: str, dec: dict) -> tuple[str, list[str], list[list[str]] | None]:
    """(heading, paragraphs, rows) of one leg's decisions (procedures.reporting.decision.decide_leg)."""
    stage = dec["stage"].replace("_", "-")
    head = f"Leg {leg}: {stage} decision: {dec['overall'].upper()}"
    if dec["overall"] == decision.NO_TOLERANCE:
        return head, [f"No decision: {dec['reason']}."], None
    rows = [["value", "value (um)", "U (um)", "limit (um)", "decision", "why"]]
    for name, v in dec["values"].items():
        rows.append([name, _f(v["value_um"]), _f(v["U_um"]), _f(v["limit_um"], "g"), v["outcome"], v["reason"]])
    return head, [f"{dec['rule']}. Leg type {dec['leg_type']}, limits from {dec['tolerance_source']}."], rows


def _grouped(contributions: list[dict]) -> list[dict]:
    """One row per source, largest first: the many target means and estimators (repeatability)
    summed in quadrature into one row naming the largest; the JSON keeps every row."""
    rows, rep = [], [c for c in contributions if c["source"] == "repeatability" and c["u_um"] > 0]
    for c in contributions:
        if c["source"] != "repeatability" and c["u_um"] > 0:
            rows.append({"source": c["source"], "quantity": c["quantity"], "u_input": f"{c['u_input']:.3g}",
                         "unit": c["unit"], "sensitivity": f"{c['sensitivity_um_per_unit']:.3g}", "u_um": c["u_um"]})
    if rep:
        top = max(rep, key=lambda c: c["u_um"])
        rows.append({"source": "repeatability", "quantity": f"{len(rep)} target means / estimators s, independent; "
                     f"largest: {top['quantity']} contributes {top['u_um']:.4f} um",
                     "u_input": "s/sqrt(n)", "unit": "um", "sensitivity": "see JSON",
                     "u_um": math.sqrt(sum(c["u_um"] ** 2 for c in rep))})
    return sorted(rows, key=lambda r: -r["u_um"])


def markdown(d: dict[str, Any]) -> str:
    lines = [f"# ISO 230-2 test report: {d['identification']['session_file'] or 'session'}", "",
             f"{d['uncertainty']}; values in um. Graph: iso230-2.png.", ""]
    for heading, paras, rows in sections(d):
        lines += [f"## {heading}", ""]
        for p in paras:
            lines += [p, ""]
        if rows:
            lines.append("| " + " | ".join(rows[0]) + " |")
            lines.append("|" + "---|" * len(rows[0]))
            lines += ["| " + " | ".join(c.replace("|", "/") for c in r) + " |" for r in rows[1:]]
            lines.append("")
    return "\n".join(lines)


# -- the graph and the PDF ------------------------------------------------------------------------------

def graph(d: dict[str, Any], path: Path) -> None:
    """Mean deviation up and down against the target with +/-2s bands, one panel per leg."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    legs = list(d["legs"])
    ncols = min(2, len(legs))
    nrows = int(math.ceil(len(legs) / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(6.2 * ncols, 3.6 * nrows), squeeze=False)
    for ax, leg in zip(axes.flat, legs):
        L = d["legs"][leg]
        for word, color, marker in (("up", "tab:blue", "^"), ("down", "tab:red", "v")):
            ts = [t for t in L["targets"] if t["direction"] == word]
            if not ts:
                continue
            x = np.array([t["target_mm"] for t in ts])
            m = np.array([t["mean_um"] for t in ts])
            s = np.array([t["s_um"] if t["s_um"] is not None else np.nan for t in ts])
            ax.plot(x, m, "-", marker=marker, ms=4, color=color, label=f"mean deviation {word}")
            ax.fill_between(x, m - 2 * s, m + 2 * s, color=color, alpha=0.15, label=f"+/-2s {word}")
            ax.plot(x, m + 2 * s, ":", lw=0.8, color=color)
            ax.plot(x, m - 2 * s, ":", lw=0.8, color=color)
        v = L["values"]
        ax.set_title(f"leg {leg}: A = {_f(v['A']['value_um'])} +/- {_f(v['A']['U_um'])} um, "
                     f"E = {_f(v['E']['value_um'])} +/- {_f(v['E']['U_um'])} um", fontsize=9)
        ax.set_xlabel("target position (mm)")
        ax.set_ylabel("deviation (um)")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.grid(alpha=0.3)
    axes.flat[0].legend(fontsize=7, loc="best")
    for ax in list(axes.flat)[len(legs):]:
        ax.axis("off")
    fig.suptitle(f"ISO 230-2: mean positional deviation with +/-2s bands ({d['error_basis']['basis']} error)",
                 fontsize=10)
    fig.tight_layout()
    try:
        with atomic_path(path, ".png") as tmp:
            fig.savefig(tmp, dpi=120)
    finally:
        plt.close(fig)


def _latin1(text: str) -> str:
    """fpdf2's core fonts hold Latin-1: replace what they cannot show."""
    for a, b in (("−", "-"), ("→", "->"), ("µ", "u"), ("…", "..."), ("≈", "~"), ("–", "-"), ("’", "'")):
        text = text.replace(a, b)
    return text.encode("latin-1", "replace").decode("latin-1")


def pdf(d: dict[str, Any], graph_png: Path, path: Path) -> None:
    """The report as a PDF (fpdf2, core fonts), the graph on a page of its own."""
    from fpdf import FPDF
    from fpdf.fonts import FontFace

    doc = FPDF(orientation="P", unit="mm", format="A4")
    doc.set_auto_page_break(True, margin=14)
    doc.set_title("ISO 230-2 test report")
    doc.set_creator("station report")
    doc.add_page()
    doc.set_font("helvetica", "B", 14)
    doc.multi_cell(0, 7, _latin1(f"ISO 230-2 test report: {Path(d['identification']['session_file']).name or 'session'}"),
                   new_x="LMARGIN", new_y="NEXT")
    doc.set_font("helvetica", "", 9)
    doc.multi_cell(0, 5, _latin1(f"{d['uncertainty']}; values in um."), new_x="LMARGIN", new_y="NEXT")
    for heading, paras, rows in sections(d):
        if heading.startswith("Leg ") and ": budget" not in heading and " decision: " not in heading:
            doc.add_page()
        doc.ln(2)
        doc.set_font("helvetica", "B", 11)
        doc.multi_cell(0, 6, _latin1(heading), new_x="LMARGIN", new_y="NEXT")
        doc.set_font("helvetica", "", 8.5)
        for p in paras:
            doc.multi_cell(0, 4.5, _latin1(p), new_x="LMARGIN", new_y="NEXT", align="L")
        if rows:
            doc.ln(1)
            widths = _col_widths(rows, doc.epw)
            with doc.table(col_widths=widths, text_align="LEFT", line_height=4.2, first_row_as_headings=True,
                           headings_style=FontFace(emphasis="BOLD")) as table:
                for r in rows:
                    row = table.row()
                    for c in r:
                        row.cell(_latin1(c))
    doc.add_page()
    doc.set_font("helvetica", "B", 11)
    doc.multi_cell(0, 6, "Graph: mean positional deviation up and down, +/-2s bands", new_x="LMARGIN", new_y="NEXT")
    doc.image(str(graph_png), w=doc.epw)
    write_bytes_atomic(path, bytes(doc.output()))


def _col_widths(rows: list[list[str]], total: float) -> tuple[float, ...]:
    longest = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    weights = [min(max(n, 9), 60) for n in longest]
    return tuple(total * w / sum(weights) for w in weights)


def write(points: np.ndarray, out_dir: str | os.PathLike, *, plan: dict, devices: dict, station_config: dict,
          attrs: dict, source: dict, raw: bool = False, identity: dict | None = None,
          tolerances: dict | None = None, stage: str | None = None) -> tuple[dict[str, Any], list[Path]]:
    """Write the four files (module docstring) into `out_dir` (which exists); their content and paths."""
    out = Path(out_dir)
    d = build(points, plan=plan, devices=devices, station_config=station_config, attrs=attrs, source=source, raw=raw,
              identity=identity, tolerances=tolerances, stage=stage)
    paths = [out / name for name in FILES]
    write_bytes_atomic(paths[0], (json.dumps(d, indent=2, allow_nan=False) + "\n").encode())
    write_bytes_atomic(paths[1], markdown(d).encode())
    graph(d, paths[2])
    pdf(d, paths[2], paths[3])
    return d, paths
