"""The diagnosis report as readable text (what `station diagnose` prints)."""

from __future__ import annotations


def _f(v, fmt=".3g", unit="") -> str:
    return "n/a" if v is None else f"{v:{fmt}}{unit}"


def _um(v, sign: bool = False) -> str:
    """A length in um with 3 significant digits; rounding noise (below 0.5 nm) shows as 0."""
    if v is None:
        return "n/a"
    if abs(v) < 5e-4:
        return "+0" if sign else "0"
    return f"{v:+.3g}" if sign else f"{v:.3g}"


def _param_line(f: dict) -> str:
    parts = []
    for k, v in f["parameters"].items():
        se = f["uncertainty"].get(k)
        parts.append(f"{k} = {v:.4g}" + (f" +/- {se:.2g}" if se is not None else ""))
    return ", ".join(parts)


VARIANT_WORDS = {"temperature": "changes with the material temperature", "position": "changes along the stroke",
                 "windup": "winds up after each reversal", "gradient": "with a gradient along the screw"}


def text_report(report: dict) -> str:
    """Findings first, then per leg: where the gap lies, candidates, what cannot be concluded."""
    lines = []
    rec = report.get("recording") or {}
    if rec.get("path"):
        lines.append(f"recording: {rec['path']}" + (f" (sha256 {rec['sha256'][:12]})" if rec.get("sha256") else ""))
    lines.append(f"twin: {report['twin']['description']}")
    st = report["settings"]
    lines.append(f"an effect is named when significant (p < {st['alpha']:g}, against the scatter between passes) and "
                 f"it explains more than {st['threshold_um']:g} um on held-out passes")
    lines.append("")
    if report["findings"]:
        lines.append("FINDINGS")
        for f in report["findings"]:
            variant = (f" ({' and '.join(VARIANT_WORDS.get(v, v) for v in f['variant'].split('+'))})"
                       if f.get("variant") else "")
            lines.append(f"  leg {f['leg']}: {f['effect']}{variant}: {_param_line(f)}")
            how = ""
            if f.get("added_with"):
                how = f" (together with {', '.join(f['added_with'])})"
            elif f.get("added_to"):
                how = f" (on top of {', '.join(f['added_to'])})"
            lines.append(f"      held-out gap {f['heldout_rms_before_um']:.3g} -> {f['heldout_rms_after_um']:.3g} um RMS{how} "
                         f"({f['shrink_pct']:.0f} % smaller), p = {f['p_value']:.2g}")
            for extra in ("sampling", "temperature_difference", "material"):
                if (f.get(extra) or {}).get("note"):
                    lines.append(f"      NOTE: {f[extra]['note']}")
    else:
        lines.append("FINDINGS: none (no candidate effect is both significant and above the threshold)")
    for key, leg in report["legs"].items():
        lines.append("")
        lines.append(f"LEG {key}: {leg['points']} points, {leg['passes']} passes ({leg['cycles']} cycles), "
                     f"{leg['targets']} targets {leg['stroke_mm'][0]:.4g}..{leg['stroke_mm'][1]:.4g} mm")
        tw = leg["twin"]
        if tw.get("kind") == "fitted" and tw.get("form") == "target means":
            lines.append(f"  twin: the mean error at each of the {tw['targets']} targets; twin held-out RMS "
                         f"{_f(tw.get('heldout_rms_um'))} um")
        elif tw.get("kind") == "fitted":
            lines.append(f"  twin: trend + {tw['sinusoids']} sinusoid(s); twin held-out RMS {_f(tw.get('heldout_rms_um'))} um"
                         + (f" (chosen with {', '.join(tw['fitted_without'])} taken out)" if tw.get("fitted_without") else ""))
        else:
            lines.append(f"  twin: {tw.get('kind')}; zero offset of the recording against it {_um(tw.get('offset_um', 0), True)} um")
        fl = leg.get("fleet")
        if fl:
            lines.append(f"  FLEET ({fl['siblings']} sibling legs of type {fl['leg_type']}, {fl['basis']}): "
                         + (fl["finding"]["note"] if fl.get("finding") else fl.get("finding_note", "")))
            if fl.get("duplicates_counted_once"):
                lines.append("    the same measurement under several names, counted once: " + ", ".join(
                    f"{k} (same as {v})" for k, v in sorted(fl["duplicates_counted_once"].items())))
            lines.append("    " + ", ".join(f"{r['feature']} {r['sigma']:+.1f}" for r in fl["features"][:4]
                                             if r.get("sigma") is not None) + " sigma")
        g = leg["gap"]
        lines.append(f"  gap: RMS {_um(g['rms_um'])} um, peak to peak {_um(g['p2p_um'])} um, mean {_um(g['mean_um'], True)} um")
        # the noise floor to 3 decimals, as station fit and station report print it; of the RAW error
        # (the diagnosis keeps thermal expansion as an effect), so it is station fit --raw's figure
        lines.append(f"  noise floor {_f(leg.get('noise_floor_um'), '.3f')} um (raw error, as station fit --raw); "
                     "repeat scatter after effects "
                     f"{_f(leg.get('repeat_scatter_after_effects_um'))} um")
        lines.append(f"  where: {leg['dominant']}")
        vs = leg["variance_share_pct"]
        lines.append("  variance of the gap: " + ", ".join(f"{k} {v:.0f} %" for k, v in vs.items()))
        bd = leg["by_direction"]
        if len(bd) == 2:
            lines.append(f"  by direction: +1 mean {_um(bd['+1']['mean_um'], True)} um, -1 mean {_um(bd['-1']['mean_um'], True)} um")
        lines.append("  by region: " + "; ".join(
            f"{r['from_mm']:.0f}..{r['to_mm']:.0f} mm RMS {_um(r['rms_um'])}" for r in leg["by_region"]))
        tr = leg.get("pass_trend")
        if tr:
            if "um_per_h" in tr:
                lines.append(f"  by pass: trend {tr['um_per_h']:+.3g} um/h (r = {tr['r']:.2f})")
            else:
                lines.append(f"  by pass: trend {tr['um_per_pass']:+.3g} um per pass (r = {tr['r']:.2f}; no time recorded)")
        cond = leg["by_condition"]
        if cond.get("material_temp"):
            c = cond["material_temp"]
            lines.append(f"  temperature: range {c['range_k']:.3g} K" +
                         (f", pass gap {c['um_per_k']:+.3g} um/K (r = {c['r']:.2f})" if c.get("um_per_k") is not None else ""))
        if cond.get("load"):
            c = cond["load"]
            lines.append(f"  load: range {c['range_n']:.0f} N" +
                         (f", pass gap {c['um_per_kn']:+.3g} um/kN (r = {c['r']:.2f})" if c.get("um_per_kn") is not None else ""))
        sp = leg["spectrum"]
        if sp.get("peaks"):
            lines.append("  spectrum peaks: " + ", ".join(f"{p['wavelength_mm']:.3g} mm {p['amplitude_um']:.3g} um"
                                                          for p in sp["peaks"]))
            lines += [f"    NOTE: {p['sampling']['note']}" for p in sp["peaks"] if p.get("sampling")][:1]
        if sp.get("lead_amplitude_um") is not None:
            lines.append(f"  at the {sp['lead_mm']:g} mm lead: {_um(sp['lead_amplitude_um'])} um"
                         + (" (a peak)" if sp.get("lead_is_peak") else ""))
        elif sp.get("lead_note"):
            lines.append(f"  lead: {sp['lead_note']}")
        if (leg.get("unexplained") or {}).get("note"):
            lines.append(f"  UNEXPLAINED: {leg['unexplained']['note']}")
        for p in leg.get("outlier_passes", []):
            lines.append(f"  outlier pass: run {p['run']} is {p['offset_um']:+.3g} um off the other passes of its direction")
        for p in leg.get("passes_explained_by_temperature", []):
            lines.append(f"  run {p['run']} is {p['offset_um']:+.3g} um off the other passes, explained by its material "
                         f"temperature ({p['temp_c']:.2f} C, {p['um_per_k']:+.3g} um/K): not an outlier")
        op = leg.get("outlier_points") or {}
        if op.get("count"):
            w = op["worst"][0]
            lines.append(f"  outlier points: {op['count']} (worst: run {w['run']} at {w['target_mm']:.4g} mm, "
                         f"{w['deviation_um']:+.3g} um off its repeats)")
        comb = leg.get("combined")
        if comb and comb["effects"]:
            lines.append(f"  all named effects ({', '.join(comb['effects'])}): held-out gap "
                         f"{comb['heldout_rms_before_um']:.3g} -> {comb['heldout_rms_after_um']:.3g} um "
                         f"({comb['shrink_pct']:.0f} % smaller)")
        for a in leg.get("alternatives") or []:
            lines.append(f"  rejected alternative: {', '.join(a['effects']) or 'nothing'}: held-out "
                         f"{a['heldout_rms_after_um']:.3g} um ({a['worse_by_um']:+.3g} um against the named; {a['reason']})")
        lines.append("  candidates:")
        for c in leg["candidates"]:
            extra = c.get("reason") or (f"explains {c['heldout_contribution_um']:.3g} um held out"
                                        if c.get("heldout_contribution_um") is not None else "")
            lines.append(f"    {c['effect']:<9} {c['status']}: {extra}")
        if leg.get("cannot_conclude"):
            lines.append("  cannot be concluded from this recording:")
            for t in leg["cannot_conclude"]:
                lines.append(f"    - {t}")
    if report.get("notes"):
        lines.append("")
        lines += [f"note: {n}" for n in report["notes"]]
    return "\n".join(lines)
