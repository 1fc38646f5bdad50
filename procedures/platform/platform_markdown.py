"""Text of the platform report: the paper's Table 2 (pose) and Table 1 (legs) as Markdown."""

from __future__ import annotations

from procedures.platform.sensitivity import POSE_ERROR_FIELDS

_ROWS = (
    ("max_original", "Maximum original error"),
    ("min_original", "Minimum original error"),
    ("max_compensated", "Maximum compensated error"),
    ("min_compensated", "Minimum compensated error"),
    ("range_reduction_pct", "Range reduction (%)"),
    ("mean_abs_original", "Mean of original abs(error)"),
    ("mean_abs_compensated", "Mean of compensated abs(error)"),
)
_LABELS = {"x_um": "x", "y_um": "y", "z_um": "z", "rx_rad": "rx", "ry_rad": "ry", "rz_rad": "rz"}


def _fmt(value, key: str, sci: bool) -> str:
    if value is None:
        return "n/a"
    if key == "range_reduction_pct":
        return f"{value:.2f} %"
    return f"{value:.4g}" if sci else f"{value:.4f}"


def _pct(value) -> str:
    return "-" if value is None else f"{value:.1f} %"


def _dominant(d: dict) -> str:
    legs = d.get("legs") or [d["leg"]]
    if len(legs) == 1:
        return f"leg {legs[0]} ({d['share_pct']:.0f} %)"
    return f"legs {', '.join(str(x) for x in legs)} ({d['share_pct']:.0f} % each)"


def _table(columns: list[tuple[str, str, dict, bool]]) -> list[str]:
    head = "| Measure | " + " | ".join(f"{label} ({unit})" for label, unit, _, _ in columns) + " |"
    lines = [head, "|---|" + "---:|" * len(columns)]
    for key, label in _ROWS:
        lines.append(f"| {label} | " + " | ".join(_fmt(stats[key], key, sci) for _, _, stats, sci in columns) + " |")
    return lines


def pose_table_markdown(summary: dict) -> str:
    """Table 2 of the paper for this run: x, y, z in um and angles in arc-seconds, then the
    angles in radians as the paper gives them."""
    pose = summary["pose"]
    cols = [(_LABELS[n], "um", pose[n], False) for n in POSE_ERROR_FIELDS[:3]]
    cols += [(_LABELS[n], "arcsec", pose[n.replace("_rad", "_arcsec")], False) for n in POSE_ERROR_FIELDS[3:]]
    rad = [(_LABELS[n], "rad", pose[n], True) for n in POSE_ERROR_FIELDS[3:]]
    return "\n".join(_table(cols) + ["", "Angles in radians:", ""] + _table(rad))


def pose_table_rows(summary: dict) -> list[tuple[str, list[str]]]:
    """The rows of `pose_table_markdown`'s first table as text cells, formatted the same way:
    (measure, [x, y, z in um, rx, ry, rz in arcsec]), for a display other than Markdown."""
    pose = summary["pose"]
    stats = [pose[n] for n in POSE_ERROR_FIELDS[:3]] + [pose[n.replace("_rad", "_arcsec")] for n in POSE_ERROR_FIELDS[3:]]
    return [(label, [_fmt(st[key], key, False) for st in stats]) for key, label in _ROWS]


def dominant_text(d: dict) -> str:
    """One `dominant_legs` entry as the report writes it: "leg 3 (24 %)", or the tied legs."""
    return _dominant(d)


def leg_table_markdown(summary: dict) -> str:
    """Table 1 of the paper for this run: leg errors at the sampled positions, um."""
    legs = summary["legs"]
    cols = [(f"leg {k}" if k != "all" else "all legs", "um", legs[k], False) for k in legs]
    return "\n".join(_table(cols))


def _label(measured) -> str:
    from procedures.platform.experiment import MEASUREMENT_LABELS

    return MEASUREMENT_LABELS.get(measured or "", "the error source's measurement")


def _columns(summary: dict) -> list[tuple[str, dict, float | None]]:
    """(label, acceptance by component, pooled leg reduction) for the main measurement and,
    when present, the other one on the same poses."""
    cols = [(_label(summary.get("measured")), summary["acceptance"], summary["legs"]["all"]["range_reduction_pct"])]
    other = summary.get("other_measurement")
    if other:
        cols.append((other["label"], other["acceptance"], other["leg_range_reduction_pct"]))
    return cols


def reduction_lines(summary: dict) -> str:
    """Plain-text lines of range reductions, one per measurement: legs pooled, then each pose
    component, and how many components shrink at least as much as the legs."""
    lines = []
    for label, acc, legs in _columns(summary):
        parts = ", ".join(f"{_LABELS[n]} {_pct(a['range_reduction_pct'])}" for n, a in acc.items())
        n_ok = sum(1 for a in acc.values() if a["at_least_leg_reduction"])
        lines.append(f"range reduction, {label}: legs {_pct(legs)}; pose {parts}; "
                     f"{n_ok} of {len(acc)} components at least as much as the legs")
    return "\n".join(lines)


def _basis_lines(summary: dict) -> list[str]:
    """Which error of the recording was used (station.services.platform_jobs: the compensation's basis)."""
    basis = (summary.get("inputs") or {}).get("error_basis")
    if not basis:
        return []
    return [f"- Error basis: {basis['basis']} (the recording's error on the compensation's basis; docs/metrology.md)",
            *[f"  - `{line.strip()}`" for line in basis.get("lines") or []]]


def report_markdown(summary: dict, geometry_text: str = "", home_sensitivity: dict | None = None) -> str:
    """The whole report (Markdown): source and settings, pose and leg tables, the acceptance
    check (pose range reduction against the legs'), dominant legs, FK outcome."""
    ws = summary["workspace"]
    lines = [
        "# Platform pose errors from leg errors, before and after compensation",
        "",
        f"- Error source: {summary['source']}",
        *_basis_lines(summary),
        *([f"- Geometry: {geometry_text}"] if geometry_text else []),
        f"- Poses: {summary['poses_used']} used of {summary['poses']} (drawn {summary['poses_drawn']} to find "
        f"{summary['poses']} within stroke and recorded range), seed {summary['seed']}",
        f"- Workspace about home: x, y +/-{ws['xy_mm']:g} mm, z +/-{ws['z_mm']:g} mm, "
        f"rx, ry +/-{ws['tilt_rad']:.4g} rad, rz +/-{ws['yaw_rad']:.4g} rad",
        "- Pose error = FK pose from erroneous leg lengths minus the nominal pose; angles are "
        "roll-pitch-yaw about fixed X, Y, Z (R = Rz Ry Rx).",
        "",
        "## Pose errors (the paper's Table 2)",
        "",
        pose_table_markdown(summary),
        "",
        "## Leg errors at the sampled positions (the paper's Table 1)",
        "",
        leg_table_markdown(summary),
        "",
        "## Range reduction: pose against legs",
        "",
    ]
    cols = _columns(summary)
    if len(cols) > 1:
        lines += [
            "On the same poses, two measurements of the leg error: the recording's systematic error (mean of "
            "its passes per direction; the paper's setting, its model against the data it was fitted to) shows "
            "what the compensation removes; one recorded pass per pose and leg adds the leg's repeatability "
            "(pass-to-pass scatter, load, temperature, drift), which no static table removes and which is "
            "independent from leg to leg.",
            "",
        ]
    lines += [
        "| Component | " + " | ".join(f"Pose, {label} | Legs (pooled) | At least as much" for label, _, _ in cols) + " |",
        "|---|" + "---:|---:|---|" * len(cols),
    ]
    for name in summary["acceptance"]:
        cells = []
        for _, acc, legs in cols:
            a = acc[name]
            cells += [_fmt(a["range_reduction_pct"], "range_reduction_pct", False), _fmt(legs, "range_reduction_pct", False),
                      "yes" if a["at_least_leg_reduction"] else "no"]
        lines.append(f"| {_LABELS[name]} | " + " | ".join(cells) + " |")
    cm = summary.get("common_mode")
    if cm:
        share, share_c = cm["common_share_of_variance_pct"], cm["compensated_common_share_of_variance_pct"]
        lines += [
            "",
            "Common and differential leg errors: the mean of the six legs at a pose (common part) moves the "
            "platform mostly along z; the deviations from it (differential part) drive x, y and the angles.",
            "",
            "| Part | Range before (um) | Range after (um) | Range reduction | Share of the leg error variance, before -> after |",
            "|---|---:|---:|---:|---:|",
            f"| common | {cm['common']['range_original']:.4f} | {cm['common']['range_compensated']:.4f} | "
            f"{_fmt(cm['common']['range_reduction_pct'], 'range_reduction_pct', False)} | "
            f"{_pct(share)} -> {_pct(share_c)} |",
            f"| differential | {cm['differential']['range_original']:.4f} | {cm['differential']['range_compensated']:.4f} | "
            f"{_fmt(cm['differential']['range_reduction_pct'], 'range_reduction_pct', False)} | |",
        ]
    lines += [
        "",
        "## Which leg dominates each pose component",
        "",
        "Mean |linearised contribution| of each leg (sensitivity d pose / d leg at each pose times the "
        "leg's error), share of the six legs.",
        "",
        "| Component | Original: leg (share) | Compensated: leg (share) | Linearisation mismatch (rel. to range) |",
        "|---|---|---|---:|",
    ]
    dom = summary["dominant_leg"]
    for a, b in zip(dom["original"], dom["compensated"]):
        mis = summary["linearisation_mismatch_rel"][a["component"]]
        lines.append(f"| {_LABELS[a['component']]} | {_dominant(a)} | {_dominant(b)} | {mis:.1e} |")
    if home_sensitivity is not None:
        lines += [
            "",
            "Sensitivity at the home pose (pose error per um of leg error; rows components, columns legs 1-6):",
            "",
            "| Component | " + " | ".join(f"leg {i}" for i in range(1, 7)) + " | dominant |",
            "|---|" + "---:|" * 6 + "---|",
        ]
        for (name, row), d in zip(home_sensitivity["matrix"].items(), home_sensitivity["dominant"]):
            lines.append(f"| {name} | " + " | ".join(f"{v:+.4f}" for v in row) + f" | {_dominant(d)} |")
    fk = summary["fk"]
    lines += [
        "",
        "## Forward kinematics",
        "",
        f"- original lengths: {', '.join(f'{k} {v}' for k, v in fk['original'].items())}",
        f"- compensated lengths: {', '.join(f'{k} {v}' for k, v in fk['compensated'].items())}",
        "",
    ]
    return "\n".join(lines)


__all__ = ["dominant_text", "leg_table_markdown", "pose_table_markdown", "pose_table_rows", "reduction_lines", "report_markdown"]
