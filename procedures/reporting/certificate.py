"""A calibration certificate of one leg (ISO/IEC 17025:2017 7.8): its content from the ISO 230-2
reports of the as-found session and, optionally, of the as-left (verification) session
(procedures.reporting.iso230_report.build, decisions included), and its PDF. docs/certificate.md.

`content(...)` gives a JSON-able dict (the certificate's JSON file); `pdf(content, path)` renders
it with fpdf2 in DejaVu Sans (µm, °C, ±) when Debian's fonts-dejavu-core is installed, else in
the core fonts with "um" / "degC". Numbering, revisions and files: station/services/certificate_jobs.py.
"""

from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import Any

from procedures.reporting import decision

TITLE = "Calibration certificate"
DECIDED_ORDER = decision.DECIDED
DEJAVU = Path("/usr/share/fonts/truetype/dejavu")
STATEMENTS = (
    "The results relate only to the item calibrated, at the time and under the conditions stated.",
    "Expanded uncertainties U are stated with a coverage factor k = 2 (about 95 % coverage for a normal "
    "distribution), evaluated after the GUM in the manner of ISO/TR 230-9.",
    "This certificate shall not be reproduced except in full without the written approval of the laboratory.",
    "All results were obtained by the laboratory itself on its own station; no part was provided externally.",
)


def _per_target(L: dict) -> list[dict[str, Any]]:
    """One row per target: mean deviation x and s up and down, B_i = x_up - x_down, the U of
    the means (um), from the ISO 230-2 report's per-target statistics."""
    rows: dict[float, dict[str, Any]] = {}
    for t in L["targets"]:
        r = rows.setdefault(round(t["target_mm"], 3), {"target_mm": t["target_mm"]})
        r[f"n_{t['direction']}"] = t["n"]
        r[f"x_{t['direction']}_um"] = t["mean_um"]
        r[f"s_{t['direction']}_um"] = t["s_um"]
        r[f"U_{t['direction']}_um"] = t["U_um"]
    out = []
    for key in sorted(rows):
        r = rows[key]
        up, down = r.get("x_up_um"), r.get("x_down_um")
        r["B_i_um"] = up - down if up is not None and down is not None else None
        out.append(r)
    return out


def _stage(iso: dict, leg: str, stage: str) -> dict[str, Any]:
    """One session's part of the certificate (as found or as left) for `leg`."""
    ident = iso["identification"]
    L = iso["legs"][leg]
    dec = (iso.get("decisions") or {}).get("legs", {}).get(leg) or {"overall": decision.NO_TOLERANCE, "values": {},
                                                                     "reason": "no decision made", "stage": stage}
    values = {}
    for name in decision.DECIDED:
        v = L["values"].get(name) or {}
        d = dec.get("values", {}).get(name) or {}
        values[name] = {"value_um": v.get("value_um"), "U_um": v.get("U_um"), "meaning": v.get("meaning", ""),
                        "limit_um": d.get("limit_um"), "decision": d.get("outcome", decision.NO_TOLERANCE),
                        "reason": d.get("reason", v.get("not_computed", "")), "dominant": d.get("dominant")}
    return {
        "stage": stage, "leg": int(leg), "session_file": Path(ident["session_file"]).name, "session_sha256": ident["session_sha256"],
        "session_id": ident["session_id"], "started_utc": ident["started_utc"], "ended_utc": ident["ended_utc"],
        "operator": ident["operator"], "outcome": ident["outcome"], "error_basis": iso["error_basis"]["statement"],
        "environment": L["environment"], "material": L["material"], "test_parameters": iso["test_parameters"],
        "compensation_state": L["compensation"], "n_targets": L["n_targets"], "n_cycles": L["n_cycles"],
        "values": values, "overall": dec["overall"], "decision_reason": dec.get("reason", ""),
        "tolerance_source": dec.get("tolerance_source"), "leg_type": dec.get("leg_type"),
        "notes": list(L["notes"]), "targets": _per_target(L),
        "specification": dec.get("specification"),
        "budget": budget_rows(L.get("budget") or {}),
    }


# -- the uncertainty budget, every contribution ---------------------------------------------------------

# every source the model knows (procedures.metrology.uncertainty._Model), in the order a reader checks them
SOURCES = ("laser", "air temperature", "air pressure", "humidity", "misalignment", "material temperature",
           "expansion coefficient", "Abbe", "dead path", "resolution", "repeatability", "near-equal extremes")


def _why_zero(source: str, inputs: dict, dn_range_ppm: float | None) -> str:
    """Why `source` contributes nothing to any value, from the inputs the budget used."""
    g = inputs.get
    if source == "misalignment":
        return ("[metrology] misalignment_mm = 0: no lateral beam walk-off stated for this set-up, so no cosine "
                "error is taken" if not g("misalignment_mm") else "no stroke to misalign over")
    if source == "Abbe":
        if not g("abbe_offset_mm"):
            return "[metrology] abbe_offset_mm = 0: the beam is stated on the leg's axis, so an angle makes no Abbe error"
        return "[metrology] abbe_angle_u_urad = 0: no angular error of the leg stated"
    if source == "dead path":
        if not g("dead_path_mm"):
            return "[metrology] dead_path_mm = 0: the laser was zeroed at the interferometer, no dead path"
        return ("the air's refractive index did not change during the test (recorded range "
                f"{dn_range_ppm or 0:.3g} ppm), so the dead path {g('dead_path_mm'):g} mm adds nothing")
    if source == "resolution":
        return "[metrology] laser_resolution_nm = 0"
    if source == "expansion coefficient":
        return "the material was at the reference temperature (or not recorded): the coefficient's error has no effect"
    if source == "near-equal extremes":
        return "each extreme is set by one target clearly above the others"
    if source == "repeatability":
        return "fewer than 2 approaches per target: no scatter estimated"
    return "its stated standard uncertainty is 0"


def budget_rows(budget: dict) -> dict[str, Any]:
    """The budget of one leg (procedures.metrology.uncertainty.LegBudget.to_json) as the certificate
    states it: one row per source with its contribution u (um, k = 1) to each decided value, the
    several places of one source (targets, positions) summed in quadrature as the budget does; a
    source that contributes nothing to any value stays listed with the reason; u_c and U (k = 2)."""
    values = budget.get("values") or {}
    inputs = budget.get("inputs") or {}
    rows = []
    for src in SOURCES:
        u = {}
        what = None
        for name in DECIDED_ORDER:
            cs = [c for c in (values.get(name) or {}).get("contributions", []) if c["source"] == src]
            if cs:
                u[name] = sum(c["u_um"] ** 2 for c in cs) ** 0.5
                what = what or cs[0]
        total = max(u.values(), default=0.0)
        row = {"source": src, "u_um": u,
               "input": (f"{what['u_input']:.3g} {what['unit']}, {what['distribution']}" if what and src not in
                         ("repeatability", "near-equal extremes") else
                         ("s / sqrt(n) and s / sqrt(2 (n - 1)) per target, type A" if src == "repeatability" and what
                          else (what or {}).get("distribution", ""))),
               "quantity": (what or {}).get("quantity", "")}
        if total <= 0:
            row["zero_because"] = _why_zero(src, inputs, budget.get("refractive_index_range_ppm"))
        rows.append(row)
    combined = {n: (values.get(n) or {}).get("u_um") for n in DECIDED_ORDER}
    expanded = {n: (values.get(n) or {}).get("U_um") for n in DECIDED_ORDER}
    return {"rows": rows, "u_c_um": combined, "U_um": expanded, "k": budget.get("k", 2.0),
            "notes": list(budget.get("notes") or []),
            "formed": {n: (values.get(n) or {}).get("formed", "") for n in DECIDED_ORDER}}


def content(as_found: dict, leg: int, *, report_no: str, revision: int, issued_utc: str, lab: dict,
            customer: str, as_left: dict | None = None, table: dict | None = None,
            supersedes: dict | None = None, instrument: dict | None = None,
            as_left_leg: int | None = None, customer_contact: str = "", simulated: list[str] | None = None,
            authoriser: dict | None = None, prepared_by: str = "", received: str = "") -> dict[str, Any]:
    """The certificate of `leg` as a JSON-able dict: `as_found` / `as_left` are ISO 230-2 report
    dicts (iso230_report.build, decided as found / as left); `lab` {name, address, accreditation};
    `table` {file, sha256, bytes} of the compensation table pushed; `supersedes` {report_no,
    revision, sha256_pdf, reason, changes} of the revision this one corrects; `instrument` the
    laser as the session identity recorded it {model, serial, calibrated_on, certificate} (over the
    config's [metrology]). `as_left_leg`: where the as-left session measured the same leg (its
    serial), when the leg was mounted at another position for the verification (default `leg`).
    `simulated`: why any device of either session was simulated (then the certificate says
    SIMULATION on every page and carries no accreditation); `authoriser` {name, role} who is to
    approve it ([lab]); the approval itself is added by `approve` (the certificate is a draft
    until then); `prepared_by` who issued it; `received` the date the item was received (ISO)."""
    key = str(leg)
    if key not in as_found["legs"]:
        raise KeyError(f"leg {leg} is not in the as-found session")
    ident = as_found["identification"]
    ins = ident["instrument"]
    li = ident["leg_identity"].get(key, {})
    simulated = list(simulated or [])
    accreditation = lab.get("accreditation") or "not accredited"
    if simulated and lab.get("accreditation"):
        # an accreditation number vouches for a real measurement: never on a simulated one
        accreditation = "not stated: the measurement was simulated (no accredited result)"
    cert = {
        "title": TITLE, "report_no": report_no, "revision": revision, "issued_utc": issued_utc,
        "supersedes": supersedes,
        "simulated": simulated,
        "laboratory": {"name": lab.get("name") or "not stated", "address": lab.get("address") or "not stated",
                       "accreditation": accreditation},
        "customer": customer or "not stated",
        "customer_contact": customer_contact or "not stated",
        "place": {"station": ident["station"]["id"], "host": ident["station"]["host"], "rig": ident["rig"],
                  "software_version": ident["software_version"]},
        "item": {"leg": leg, "serial": li.get("serial", "not recorded"), "part_number": li.get("part_number", "not stated"),
                 "leg_type": li.get("leg_type", "not stated"), "screw_lot": li.get("screw_lot", "not stated"),
                 "drive": ident["legs"].get(key, "not recorded"), "received": received or "not stated"},
        "instrument": {"model": ins["model"], "serial": ins["serial"], "reported_identity": ins["reported_identity"],
                       "calibration_date": ins["calibration_date"], "calibration_due": ins["calibration_due"],
                       "calibration_certificate": "not stated",
                       "traceable": bool(ins["traceable"]), "warnings": list(ins["calibration_warnings"]),
                       "wavelength_nm": ins["wavelength_nm"], "laser_accuracy_ppm_k2": ins["laser_accuracy_ppm_k2"],
                       "resolution_nm": ins["resolution_nm"], "air_compensation": ident["air_compensation"]},
        "method": {"standard": "ISO 230-2:2014, positioning accuracy and repeatability (bidirectional)",
                   "uncertainty": as_found["uncertainty"], "decision_rule": decision.RULE,
                   "tolerance_source": None, "specification": None,
                   "sampling": "not applicable: the item submitted was calibrated itself, no sample was taken"},
        "as_found": _stage(as_found, key, "as_found"),
        "as_left": None,
        "compensation_table": table,
        "statements": list(STATEMENTS),
        "approval": {"prepared_by": prepared_by or ident["operator"] or "not recorded",
                     "authoriser": (authoriser or {}).get("name") or "not stated",
                     "authoriser_role": (authoriser or {}).get("role") or "not stated",
                     "status": "draft", "approved_by": None, "approved_role": None, "approved_utc": None,
                     "audit_id": None, "operator": ident["operator"]},
    }
    cert["method"]["tolerance_source"] = cert["as_found"]["tolerance_source"]
    cert["method"]["specification"] = cert["as_found"]["specification"]
    for key_from, key_to in (("model", "model"), ("serial", "serial"), ("calibrated_on", "calibration_date"),
                             ("certificate", "calibration_certificate")):
        if (instrument or {}).get(key_from):
            cert["instrument"][key_to] = instrument[key_from]
    ci = cert["instrument"]
    said = str(ci["reported_identity"])
    if ci["serial"] not in ("not stated", "", None) and said not in ("not recorded", "") and ci["serial"] not in said:
        ci["identity_mismatch"] = (f"CHECK THE INSTRUMENT: the laser connected reported itself as '{said}', which does "
                                   f"not name the serial {ci['serial']} whose calibration is stated here.")
    if as_left is not None:
        lkey = str(leg if as_left_leg is None else as_left_leg)
        if lkey not in as_left["legs"]:
            raise KeyError(f"leg {lkey} is not in the as-left session")
        left_serial = as_left["identification"]["leg_identity"].get(lkey, {}).get("serial")
        if left_serial != cert["item"]["serial"]:
            raise ValueError(f"the as-left session measured leg {left_serial}, the as-found session "
                             f"{cert['item']['serial']}")
        cert["as_left"] = _stage(as_left, lkey, "as_left")
        lins = as_left["identification"]["instrument"]
        if not lins["traceable"]:  # the as-left laser counts as much as the as-found one
            ci["traceable"] = False
            ci["warnings"] += [f"as left: {w}" for w in lins["calibration_warnings"]] or \
                ["as left: the laser's calibration due date is not stated"]
    cert["traceability"] = traceability(cert)
    return cert


def traceability(c: dict) -> dict[str, Any]:
    """Whether the certificate may say its results are traceable to the SI, and the sentence it
    says: only when the instrument was in calibration on the day, its identity matches the serial
    whose calibration is stated, and nothing was simulated; otherwise the sentence says why not,
    so it can never stand under a warning that contradicts it."""
    ins = c["instrument"]
    why_not = []
    if c.get("simulated"):
        why_not.append("the measurement was simulated (" + "; ".join(c["simulated"]) + ")")
    if not ins["traceable"]:
        why_not.append("the laser interferometer was not in calibration on the day of the measurement ("
                       + ("; ".join(ins["warnings"]) or "no calibration due date stated") + ")")
    if ins.get("identity_mismatch"):
        why_not.append(f"the laser connected did not identify itself as serial {ins['serial']}, whose calibration is "
                       "stated")
    if why_not:
        return {"traceable": False, "reasons": why_not,
                "statement": "NOT TRACEABLE. " + "; ".join(why_not)[0].upper() + "; ".join(why_not)[1:] + ". The results "
                             "below are NOT traceable to the SI unit of length and this document cannot serve as "
                             "evidence of conformity."}
    cert_no = ins.get("calibration_certificate") or "not stated"
    chain = (f"the laser interferometer {ins['model']} serial {ins['serial']}, calibrated on {ins['calibration_date']} "
             f"(certificate {cert_no}), due {ins['calibration_due']}, in calibration on the day of the measurement; "
             "its vacuum wavelength realises the metre")
    return {"traceable": True, "reasons": [],
            "statement": f"The results are traceable to the SI unit of length, the metre, through {chain}. The air "
                         f"refractive index is compensated from the air sensors ({ins['air_compensation']})."}


# -- the PDF ------------------------------------------------------------------------------------------

class _Text:
    """Unicode text with DejaVu, else the core fonts' Latin-1 with ASCII units."""

    def __init__(self, doc):
        regular, bold = DEJAVU / "DejaVuSans.ttf", DEJAVU / "DejaVuSans-Bold.ttf"
        self.unicode = regular.exists() and bold.exists()
        if self.unicode:
            doc.add_font("dejavu", "", str(regular))
            doc.add_font("dejavu", "B", str(bold))
            self.family = "dejavu"
        else:
            self.family = "helvetica"

    def __call__(self, s: Any) -> str:
        s = str(s)
        if self.unicode:
            return s.replace("+/-", "±").replace("<=", "≤").replace(" um", " µm").replace("(um)", "(µm)") \
                .replace("degC", "°C").replace("u^2", "u²").replace("um/m/K", "µm/(m·K)")
        for a, b in (("µ", "u"), ("°C", "degC"), ("±", "+/-"), ("≤", "<="), ("²", "^2"), ("·", "*"), ("−", "-")):
            s = s.replace(a, b)
        return s.encode("latin-1", "replace").decode("latin-1")


def _num(v: Any, spec: str = ".3f") -> str:
    return "–" if v is None else format(v, spec)


def _signed(v: Any) -> str:
    return "–" if v is None else f"{v:+.3f}"


def _when(iso: str) -> str:
    """An ISO time to the second, without the zone (stated as UTC beside it)."""
    try:
        return _dt.datetime.fromisoformat(iso).strftime("%Y-%m-%d %H:%M:%S")
    except (TypeError, ValueError):
        return iso or "not recorded"


def _rng(r: Any, spec: str = ".2f") -> str:
    return "not recorded" if not r else f"{r[0]:{spec}} to {r[1]:{spec}}"


def _blocks(c: dict) -> list[tuple]:
    """The certificate as blocks: ("h", heading) / ("p", text) / ("kv", [(key, value)]) /
    ("table", header, rows, aligns) / ("box", text) / ("graph", stage) / ("sign", approval). A
    heading is kept with the block after it."""
    b: list[tuple] = []
    lab, item, ins = c["laboratory"], c["item"], c["instrument"]
    af = c["as_found"]
    if c.get("simulated"):
        b.append(("box", "SIMULATION. At least one device of this measurement was simulated ("
                         + "; ".join(c["simulated"]) + "). This document certifies no real item and carries no "
                         "accreditation."))
    if c.get("supersedes"):
        s = c["supersedes"]
        b.append(("box", f"This revision {c['revision']} supersedes revision {s['revision']} of certificate "
                         f"{s['report_no']} (PDF sha256 {s['sha256_pdf'][:16]}…), which is withdrawn. "
                         f"Reason: {s['reason']}"))
        changes = s.get("changes") or []
        b.append(("h", f"Changes from revision {s['revision']}"))
        if changes:
            b.append(("table", ["field", f"revision {s['revision']}", f"revision {c['revision']}"],
                      [[ch["field"], str(ch["before"]), str(ch["after"])] for ch in changes], "LLL"))
        else:
            b.append(("p", "No field of the certificate changed (the revision re-issues the same content)."))
    b.append(("h", "1. Laboratory and customer"))
    b.append(("kv", [("Laboratory", lab["name"]), ("Address", lab["address"]), ("Accreditation", lab["accreditation"]),
                     ("Place of calibration", f"station {c['place']['station']} (host {c['place']['host']}, "
                                              f"{c['place']['rig']} rig), software {c['place']['software_version']}"),
                     ("Customer", c["customer"]), ("Customer contact", c.get("customer_contact") or "not stated")]))
    b.append(("h", "2. Item calibrated"))
    b.append(("kv", [("Item", f"ball-screw leg of a hexapod, serial {item['serial']}"),
                     ("Part number / type", f"{item['part_number']} / {item['leg_type']}"),
                     ("Screw lot", item["screw_lot"]), ("Position on the station", f"leg {item['leg']}"),
                     ("Drive", item["drive"]), ("Received", item.get("received") or "not stated"),
                     ("Condition", f"as received; compensation at the start: {af['compensation_state']}")]))
    b.append(("h", "3. Measuring instrument and traceability"))
    b.append(("kv", [("Laser interferometer", f"{ins['model']}, serial {ins['serial']} (reports itself as "
                                              f"'{ins['reported_identity']}')"),
                     ("Calibrated on / due", f"{ins['calibration_date']} / {ins['calibration_due']}"),
                     ("Its certificate", ins.get("calibration_certificate") or "not stated"),
                     ("Wavelength, accuracy", f"{ins['wavelength_nm']:.3f} nm vacuum, {ins['laser_accuracy_ppm_k2']:g} ppm "
                                              f"(k = 2), resolution {ins['resolution_nm']:g} nm"),
                     ("Air compensation", ins["air_compensation"])]))
    if ins.get("identity_mismatch"):
        b.append(("box", ins["identity_mismatch"]))
    tr = c.get("traceability") or traceability(c)
    b.append(("box", tr["statement"]) if not tr["traceable"] else ("p", tr["statement"]))
    b.append(("h", "4. Method"))
    tp = af["test_parameters"]
    spec = c["method"].get("specification")
    if spec:
        limits = f"{spec} (limits for type {item['leg_type']})"
    elif c["method"]["tolerance_source"]:
        limits = (f"limits for type {item['leg_type']} set by the laboratory; no specification identifier stated "
                  "(spec / spec_revision in [tolerances.TYPE])")
    else:
        limits = "none stated for this leg type: no conformity decision"
    b.append(("kv", [("Standard", c["method"]["standard"]),
                     ("Test", f"{af['n_targets']} targets from {min(tp['targets_mm'], default=0):g} to "
                              f"{max(tp['targets_mm'], default=0):g} mm, {af['n_cycles']} approaches per target and "
                              f"direction; feed {tp['feed_statement']}; dwell "
                              + (f"{tp['dwell_s']:g} s" if tp.get("dwell_s") is not None else "not recorded")),
                     ("Approach", tp["approach"]),
                     ("Uncertainty", c["method"]["uncertainty"] + "; every contribution in the budget sections below"),
                     ("Decision rule", c["method"]["decision_rule"]),
                     ("Specification", limits),
                     ("Sampling", c["method"].get("sampling") or "not applicable")]))
    stages = [("as found", af)] + ([("as left", c["as_left"])] if c.get("as_left") else [])
    n = 5
    for word, st in stages:
        b.append(("h", f"{n}. Environment and conditions, {word}"))
        e = st["environment"]
        b.append(("kv", [("Session", f"{st['session_file']} (sha256 {st['session_sha256'][:16]}…), "
                                     f"{st['outcome']}; leg position {st['leg']}"
                                     + (f"; {st['kind']}" if st.get("kind") else "")),
                         ("Date of measurement", f"{_when(st['started_utc'])} to {_when(st['ended_utc'])} (UTC)"),
                         ("Operator", st["operator"] or "not recorded"),
                         ("Air temperature", f"{_rng(e['air_temp_c'])} degC"),
                         ("Material temperature", f"{_rng(e['material_temp_c'])} degC"),
                         ("Pressure, humidity", f"{_rng(e['pressure_hpa'], '.1f')} hPa, "
                                                f"{_rng(e['humidity_pct'], '.1f')} %RH"),
                         ("Expansion coefficient", f"{st['material']['expansion_um_m_k']:g} ± "
                                                   f"{st['material']['expansion_u_um_m_k']:g} um/m/K (u, k = 1)"),
                         ("Temperature basis", st["error_basis"])]))
        n += 1
    for word, st in stages:
        b.append(("h", f"{n}. Results {word} (ISO 230-2, U with k = 2): {st['overall'].upper()}"))
        rows = []
        for name, v in st["values"].items():
            rows.append([name, v["meaning"], _num(v["value_um"]), _num(v["U_um"]), _num(v["limit_um"], "g"),
                         v["decision"]])
        b.append(("table", ["value", "meaning", "result (um)", "U (um)", "limit (um)", "decision"], rows,
                  "LLRRRL"))
        why = [f"{name}: {v['reason']}" for name, v in st["values"].items()
               if v["decision"] in (decision.UNDECIDED, decision.NOT_CONFORM)]
        if st["overall"] == decision.NO_TOLERANCE:
            why = [f"No decision: {st['decision_reason']}."]
        for w in why:
            b.append(("p", w))
        for note in st["notes"]:
            b.append(("p", f"Note: {note}"))
        n += 1
    for word, st in stages:
        b.append(("h", f"{n}. Deviation graph {word}"))
        b.append(("graph", st, word))
        n += 1
    for word, st in stages:
        b.append(("h", f"{n}. Per-target results {word} (um)"))
        rows = [[f"{t['target_mm']:.3f}", _signed(t.get("x_up_um")), _num(t.get("s_up_um")), _num(t.get("U_up_um")),
                 _signed(t.get("x_down_um")), _num(t.get("s_down_um")), _num(t.get("U_down_um")), _signed(t["B_i_um"])]
                for t in st["targets"]]
        b.append(("table", ["target (mm)", "x↑", "s↑", "U(x↑)", "x↓", "s↓", "U(x↓)", "B_i"], rows, "RRRRRRRR"))
        b.append(("p", "x: mean positional deviation (measured − target) at the target, ↑ approached in the positive "
                       "direction, ↓ in the negative; s: estimator of the standard deviation of the approaches; U(x): "
                       "expanded uncertainty of the mean (k = 2); B_i = x↑ − x↓: reversal value at the target."))
        n += 1
    for word, st in stages:
        bud = st.get("budget")
        if not bud:
            continue
        b.append(("h", f"{n}. Uncertainty budget {word}: contributions u in um (k = 1)"))
        names = list(DECIDED_ORDER)
        rows = []
        for r in bud["rows"]:
            if r.get("zero_because"):  # listed all the same, with why it is nothing
                rows.append([r["source"], f"0: {r['zero_because']}"] + ["0"] * len(names))
                continue
            rows.append([r["source"], r["input"] or "–"] + [_num(r["u_um"].get(k), ".4f") if k in r["u_um"] else "–"
                                                              for k in names])
        rows.append(["combined u_c", ""] + [_num(bud["u_c_um"].get(k), ".4f") for k in names])
        rows.append([f"U (k = {bud['k']:g})", ""] + [_num(bud["U_um"].get(k), ".3f") for k in names])
        b.append(("table", ["source", "input: standard uncertainty, distribution"] + names, rows,
                  "LL" + "R" * len(names)))
        b.append(("p", "A source counts once per value; its places (targets, positions) are summed in quadrature. "
                       "–: the source does not enter that value (at one target, as in B and R, the "
                       "length-proportional terms cancel). 0: the source is in the model but contributes nothing "
                       "here, for the reason given."))
        for note in bud.get("notes") or []:
            b.append(("p", f"Note: {note}"))
        n += 1
    b.append(("h", f"{n}. Compensation table"))
    t = c.get("compensation_table")
    b.append(("kv", [("Table pushed", t["file"] if t else "none given (no --table)"),
                     ("sha256 of the file", t["sha256"] if t else "–")]
              + ([("sha256 of the leg's rows", t["leg_rows_sha256"])] if t and t.get("leg_rows_sha256") else [])
              + ([("Active as left", c["as_left"]["compensation_state"])] if c.get("as_left") else [])
              + ([("Active table sha256", (t.get("active_as_left_sha256") or "not recorded") + (
                  ": the table pushed" if t.get("matches_as_left") else ""))]
                 if t and c.get("as_left") and "matches_as_left" in t else [])))
    if t and t.get("matches_as_left") is False:
        b.append(("box", "The table active during the as-left measurement is NOT the table named above: the as-left "
                         "results do not show the effect of that table."))
    n += 1
    b.append(("h", f"{n}. Statements"))
    for s in c["statements"]:
        b.append(("p", s))
    n += 1
    b.append(("h", f"{n}. Approval"))
    b.append(("sign", c["approval"]))
    b.append(("end", f"End of certificate {c['report_no']} revision {c['revision']}"))
    return b


def pdf(c: dict) -> bytes:
    """The certificate as PDF bytes (written by the caller): A4, a header with the report number
    and "page x of y" on every page, headings kept with their blocks, number columns sized to
    their widest value so nothing wraps."""
    from fpdf import FPDF
    from fpdf.enums import XPos, YPos

    issued = c["issued_utc"][:10]
    ident = f"{c['report_no']} rev. {c['revision']}"
    banner_sim = "SIMULATION: not a calibration of a real item" if c.get("simulated") else ""
    appr = c.get("approval") or {}
    banner_draft = ("DRAFT: not valid until approved"
                    if appr.get("status") != "approved" else "")

    class Doc(FPDF):
        def header(self):
            self.set_font(t.family, "B", 9)
            name = c["laboratory"]["name"]
            self.cell(0, 5, t(f"{name if name != 'not stated' else 'Laboratory not stated'}   ·   {TITLE}"),
                      new_x=XPos.LMARGIN, new_y=YPos.NEXT)
            self.set_font(t.family, "", 8)
            self.cell(self.epw / 2, 4, t(f"Certificate {ident}, issued {issued}"))
            self.cell(self.epw / 2, 4, t(f"Page {self.page_no()} of {{nb}}"), align="R",
                      new_x=XPos.LMARGIN, new_y=YPos.NEXT)
            # on every page, so no page taken out of the document can pass for a real or approved one
            for mark in (m for m in (banner_sim, banner_draft) if m):
                self.set_text_color(190, 0, 0)
                self.set_font(t.family, "B", 9)
                self.cell(0, 4.5, t(mark), align="C", new_x=XPos.LMARGIN, new_y=YPos.NEXT)
                self.set_text_color(0, 0, 0)
            self.line(self.l_margin, self.get_y() + 1, self.l_margin + self.epw, self.get_y() + 1)
            self.ln(4)

        def footer(self):
            self.set_y(-12)
            self.set_font(t.family, "", 7)
            self.cell(0, 4, t(f"Certificate {ident}. Reproduction only in full. Page {self.page_no()} of {{nb}}"),
                      align="C")

    doc = Doc(orientation="P", unit="mm", format="A4")
    t = _Text(doc)
    doc.alias_nb_pages()
    doc.set_margins(16, 14, 16)
    doc.set_auto_page_break(True, margin=16)
    doc.set_title(f"{TITLE} {ident}")
    doc.set_creator("station certificate")
    doc.add_page()
    doc.set_font(t.family, "B", 16)
    doc.cell(0, 9, t(TITLE), new_x=XPos.LMARGIN, new_y=YPos.NEXT)
    doc.set_font(t.family, "", 10)
    doc.cell(0, 5, t(f"Certificate number {c['report_no']}, revision {c['revision']}; date of issue {issued}"),
             new_x=XPos.LMARGIN, new_y=YPos.NEXT)
    doc.ln(2)
    blocks = _blocks(c)
    for i, blk in enumerate(blocks):
        kind = blk[0]
        if kind == "h":
            # keep the heading with the block after it (and a table's first rows at least)
            nxt = blocks[i + 1] if i + 1 < len(blocks) else ("p", "")
            whole = 10 + _height(doc, t, nxt)
            fits_a_page = whole < doc.page_break_trigger - doc.t_margin - 20
            need = whole if fits_a_page else 10 + _height(doc, t, nxt, first_only=True)
            if doc.get_y() + need > doc.page_break_trigger:
                doc.add_page()
            doc.ln(2)
            doc.set_font(t.family, "B", 11)
            doc.multi_cell(0, 6, t(blk[1]), new_x=XPos.LMARGIN, new_y=YPos.NEXT, align="L")
        elif kind == "p":
            doc.set_font(t.family, "", 8.5)
            doc.multi_cell(0, 4.3, t(blk[1]), new_x=XPos.LMARGIN, new_y=YPos.NEXT, align="L")
        elif kind == "kv":
            _kv(doc, t, blk[1])
        elif kind == "table":
            _table(doc, t, blk[1], blk[2], blk[3])
        elif kind == "box":
            _box(doc, t, blk[1])
        elif kind == "sign":
            _sign(doc, t, blk[1])
        elif kind == "graph":
            _graph(doc, t, blk[1], blk[2])
        elif kind == "end":
            doc.ln(4)
            doc.set_font(t.family, "B", 9)
            doc.cell(0, 5, t(f"— {blk[1]} —"), align="C", new_x=XPos.LMARGIN, new_y=YPos.NEXT)
    return bytes(doc.output())


def _kv_width(doc, t, items) -> float:
    doc.set_font(t.family, "B", 8.5)
    return min(max(doc.get_string_width(t(k)) for k, _ in items) + 4, 58)


def _height(doc, t, blk, first_only: bool = False) -> float:
    """About how much room `blk` takes (mm); `first_only`: of a table, the heading and 3 rows."""
    if blk[0] == "kv":
        return sum(4.6 * max(1, _lines(doc, t, v, doc.epw - _kv_width(doc, t, blk[1]))) for _, v in blk[1])
    if blk[0] == "table":
        return 5.2 * (1 + (min(3, len(blk[2])) if first_only else len(blk[2])))
    if blk[0] == "box":
        return 6 + 4.6 * _lines(doc, t, blk[1], doc.epw - 8)
    if blk[0] == "sign":
        return 40
    if blk[0] == "graph":
        return GRAPH_H + 14
    return 4.3 * max(1, _lines(doc, t, blk[1] if len(blk) > 1 else "", doc.epw))


def _lines(doc, t, text: str, width: float) -> int:
    doc.set_font(t.family, "", 8.5)
    return max(1, int(doc.get_string_width(t(text)) / max(width - 2, 1)) + 1)


def _kv(doc, t, items) -> None:
    from fpdf.enums import XPos, YPos

    kw = _kv_width(doc, t, items)
    if doc.get_y() + _height(doc, t, ("kv", items)) > doc.page_break_trigger:
        doc.add_page()
    for k, v in items:
        y = doc.get_y()
        doc.set_font(t.family, "B", 8.5)
        doc.multi_cell(kw, 4.6, t(k), new_x=XPos.RIGHT, new_y=YPos.TOP)
        doc.set_font(t.family, "", 8.5)
        doc.multi_cell(doc.epw - kw, 4.6, t(v), new_x=XPos.LMARGIN, new_y=YPos.NEXT, align="L")
        doc.set_y(max(doc.get_y(), y + 4.6))


def _table(doc, t, header: list[str], rows: list[list[str]], aligns: str) -> None:
    """Columns of numbers as wide as their widest cell (never wrapped); text columns share the rest."""
    from fpdf.fonts import FontFace

    size = 8.0
    doc.set_font(t.family, "B", size)
    natural = [max([doc.get_string_width(t(header[i]))] + [doc.get_string_width(t(r[i])) for r in rows]) + 3.5
               for i in range(len(header))]
    widths = list(natural)
    if sum(widths) > doc.epw:  # shrink only the text columns (left-aligned), never the numbers
        # a short text column (a name) keeps its width, so its words never break mid-word; the long
        # ones (sentences) share what is left and wrap between words
        text_cols = ([i for i, a in enumerate(aligns) if a == "L" and natural[i] > 40]
                     or [i for i, a in enumerate(aligns) if a == "L"])
        fixed = sum(w for i, w in enumerate(widths) if i not in text_cols)
        room = max(doc.epw - fixed, 10 * len(text_cols))
        total_text = sum(widths[i] for i in text_cols) or 1
        for i in text_cols:
            widths[i] = room * widths[i] / total_text
    else:  # spread the slack over the text columns (or all)
        slack = doc.epw - sum(widths)
        grow = [i for i, a in enumerate(aligns) if a == "L"] or list(range(len(widths)))
        for i in grow:
            widths[i] += slack / len(grow)
    if doc.get_y() + 5.2 * (1 + min(len(rows), 3)) > doc.page_break_trigger:
        doc.add_page()
    doc.set_font(t.family, "", size)
    align = {"L": "LEFT", "R": "RIGHT", "C": "CENTER"}
    with doc.table(col_widths=widths, width=min(sum(widths), doc.epw), align="LEFT", line_height=4.6, first_row_as_headings=True,
                   headings_style=FontFace(emphasis="BOLD", fill_color=(230, 230, 230)),
                   text_align=tuple(align[a] for a in aligns), repeat_headings=1) as table:
        for r in [header] + rows:
            row = table.row()
            for cell in r:
                row.cell(t(cell))
    doc.ln(1.5)


def _box(doc, t, text: str) -> None:
    from fpdf.enums import XPos, YPos

    doc.ln(1)
    if doc.get_y() + _height(doc, t, ("box", text)) > doc.page_break_trigger:
        doc.add_page()
    doc.set_draw_color(200, 0, 0)
    doc.set_line_width(0.8)
    doc.set_text_color(170, 0, 0)
    doc.set_font(t.family, "B", 9.5)
    doc.multi_cell(0, 5, t(text), border=1, padding=2.5, new_x=XPos.LMARGIN, new_y=YPos.NEXT, align="L")
    doc.set_text_color(0, 0, 0)
    doc.set_draw_color(0, 0, 0)
    doc.set_line_width(0.2)
    doc.ln(2)


def _sign(doc, t, approval: dict) -> None:
    """Who measured, who prepared (issued) the certificate, and who approved it: name, function and
    time of the electronic approval (`station certificate approve`); a draft says it awaits the
    authoriser named in the config."""
    from fpdf.enums import XPos, YPos

    if doc.get_y() + 40 > doc.page_break_trigger:
        doc.add_page()
    a = approval
    rows = [("Measurement performed by", f"{a.get('operator') or 'not recorded'} (operator recorded in the session)"),
            ("Prepared (issued) by", a.get("prepared_by") or "not recorded")]
    if a.get("status") == "approved":
        rows.append(("Approved by", f"{a['approved_by']}, {a.get('approved_role') or 'function not stated'}"))
        rows.append(("Approved on", f"{_when(a['approved_utc'])} UTC, electronically (`station certificate approve`; "
                                    f"audit entry {a.get('audit_id') or 'not recorded'})"))
        rows.append(("Validity", "This approved document is the certificate. It is not signed by hand: any change "
                                 "makes another document (its sha256 is in the laboratory's catalog)."))
    else:
        rows.append(("Approved by", f"NOT YET APPROVED. To be approved by {a.get('authoriser') or 'not stated'}, "
                                    f"{a.get('authoriser_role') or 'function not stated'} ([lab] authoriser)"))
        rows.append(("Validity", "This draft is not a valid certificate until it is approved."))
    _kv(doc, t, rows)
    doc.set_y(doc.get_y() + 2)
    doc.set_x(doc.l_margin)
    doc.set_font(t.family, "", 8.5)
    doc.cell(0, 4, "", new_x=XPos.LMARGIN, new_y=YPos.NEXT)


GRAPH_H = 62.0


def _graph(doc, t, st: dict, word: str) -> None:
    """The ISO 230-2 graph of one stage: the mean deviation at each target, up and down, with the
    x ± 2s band of each direction (dashed), drawn in vectors on the page."""
    from fpdf.enums import XPos, YPos

    rows = st["targets"]
    xs = [r["target_mm"] for r in rows]
    series = []
    for d, colour in (("up", (0, 70, 170)), ("down", (190, 40, 0))):
        mean = [(r["target_mm"], r.get(f"x_{d}_um"), r.get(f"s_{d}_um") or 0.0) for r in rows
                if r.get(f"x_{d}_um") is not None]
        series.append((d, colour, mean))
    ys = [v for _, _, m in series for _, x, sd in m for v in (x - 2 * sd, x + 2 * sd)]
    if len(xs) < 2 or not ys:
        doc.set_font(t.family, "", 8.5)
        doc.multi_cell(0, 4.3, t("Not drawn: fewer than two targets."), new_x=XPos.LMARGIN, new_y=YPos.NEXT)
        return
    if doc.get_y() + GRAPH_H + 14 > doc.page_break_trigger:
        doc.add_page()
    x0, y0 = doc.l_margin + 14, doc.get_y() + 2
    w, h = doc.epw - 16, GRAPH_H - 10
    lo, hi = min(ys + [0.0]), max(ys + [0.0])
    pad = 0.08 * ((hi - lo) or 1.0)
    lo, hi = lo - pad, hi + pad
    xl, xh = min(xs), max(xs)

    def px(v):
        return x0 + (v - xl) / ((xh - xl) or 1.0) * w

    def py(v):
        return y0 + h - (v - lo) / ((hi - lo) or 1.0) * h

    doc.set_line_width(0.2)
    doc.set_draw_color(0, 0, 0)
    doc.rect(x0, y0, w, h)
    doc.set_font(t.family, "", 6.5)
    for i in range(5):  # y ticks
        v = lo + (hi - lo) * i / 4
        doc.set_draw_color(215, 215, 215)
        doc.line(x0, py(v), x0 + w, py(v))
        doc.set_xy(doc.l_margin, py(v) - 1.5)
        doc.cell(13, 3, t(f"{v:.2f}"), align="R")
    for i in range(5):  # x ticks
        v = xl + (xh - xl) * i / 4
        doc.set_xy(px(v) - 10, y0 + h + 0.5)
        doc.cell(20, 3, t(f"{v:g}"), align="C")
    doc.set_draw_color(120, 120, 120)
    if lo < 0 < hi:
        doc.line(x0, py(0.0), x0 + w, py(0.0))
    for d, colour, m in series:
        doc.set_draw_color(*colour)
        doc.set_line_width(0.45)
        doc.polyline([(px(p), py(x)) for p, x, _ in m])
        doc.set_line_width(0.2)
        with doc.local_context():
            doc.set_dash_pattern(dash=1.2, gap=0.8)
            for sign in (1, -1):
                doc.polyline([(px(p), py(x + sign * 2 * sd)) for p, x, sd in m])
        for p, x, _ in m:
            doc.rect(px(p) - 0.5, py(x) - 0.5, 1, 1)  # the measured mean itself
    doc.set_draw_color(0, 0, 0)
    doc.set_xy(x0, y0 + h + 4)
    doc.set_font(t.family, "", 7.5)
    doc.multi_cell(w, 3.6, t(f"Mean positional deviation (um) against the target (mm), {word}: blue ↑ positive "
                             "direction, red ↓ negative direction, solid the mean x, dashed x ± 2s."),
                   new_x=XPos.LMARGIN, new_y=YPos.NEXT, align="C")
    doc.ln(2)


def now_utc() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
