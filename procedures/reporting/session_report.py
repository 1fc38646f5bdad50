"""Session report: PNG plots and a summary table (Markdown and JSON) of errors before and after
compensation by a leg-error model.

Files written into the output directory:
- errors.png      error per leg and direction (points) with the model (lines)
- residuals.png   residual (error minus model) per leg and direction
- histograms.png  error before / after compensation per leg, like the paper's Figs. 7-8
- spectrum.png    amplitude spectrum of the residual per leg, screw lead and harmonics marked
- summary.md, summary.json  per-leg figures (um)
- iso230-2.md, .json, .png, .pdf  the ISO 230-2 test report with the expanded uncertainty of every
  value (procedures.reporting.iso230_report; written when the session's metadata is given)

"After compensation" is the residual (error minus model) on this session's points: in-sample
when the model was fitted to this session, a true test when it came from another recording. Its
figures are the "residual range" and "residual RMS" (not the "held-out range" of `station fit`,
which scores each cycle with a model fitted without it). The model's own held-out figures are
quoted from the model as "model held-out RMS" and "model held-out ratio". Names and definitions:
docs/figures.md.

Which error (docs/metrology.md): the fit, plots, summary and ISO 230-2 part all use one basis,
the same as `station fit`: the error normalised to 20 degC material temperature by default, the
raw `error_um` with `raw=True` (`--raw`). With a model, the basis the model records
(`options.error_basis`, written by `station fit`; a model without it was fitted to the raw
error): a normalised model with `raw=True` is refused (it would be compared with another error
than it was fitted to). summary.md/json state the basis (`error_basis`).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from procedures.io.atomic_outputs import atomic_folder, write_text_atomic
from procedures.vocabulary import InputError
from procedures.fit import LegErrorModel, fit
from procedures.fit.bidirectional import MIN_POINTS_PER_WAVE, pair_amplitudes
from procedures.fit.data import LegData, split_legs
from procedures.fit.figures import range_um, reduction_pct, rms_about_mean_um
from procedures.fit.noise import estimate_noise_floor
from procedures.reporting.iso230 import MEANINGS as ISO_MEANINGS
from procedures.reporting.iso230_report import json_safe  # JSON with NaN/inf as null, numpy scalars as numbers

UP_COLOR = "tab:blue"
DOWN_COLOR = "tab:red"


@dataclass
class ReportResult:
    out_dir: Path
    files: list[Path] = field(default_factory=list)
    summary: dict[str, Any] = field(default_factory=dict)
    iso230: dict[str, Any] | None = None  # the ISO 230-2 test report (procedures.reporting.iso230_report.build)


def _lead_of(model: LegErrorModel, leg: int) -> float | None:
    fit_ = model.legs[leg]
    basis = getattr(fit_, "basis", None)
    if basis is not None and basis.lead_mm and basis.lead_harmonics:
        return float(basis.lead_mm)
    return None


def residual_spectrum(data: LegData, residual_um: np.ndarray, n_freq: int = 600) -> tuple[np.ndarray, np.ndarray]:
    """(wavelength_mm, amplitude_um) of sin + cos pairs fitted to the per-cell mean residual,
    from the stroke length down to 2.2 target spacings (shorter waves alias)."""
    keys = np.stack([data.position_mm, data.direction.astype(float)], 1)
    cells, ids = np.unique(keys, axis=0, return_inverse=True)
    ids = ids.ravel()
    rm = np.bincount(ids, weights=residual_um) / np.bincount(ids)
    xm = cells[:, 0]
    span = float(np.ptp(xm))
    spacing = data.target_spacing_mm()
    if span <= 0 or spacing <= 0 or xm.size < 4:
        return np.empty(0), np.empty(0)
    f_lo, f_hi = 1.0 / span, 1.0 / (MIN_POINTS_PER_WAVE * spacing)
    if f_hi <= f_lo:
        return np.empty(0), np.empty(0)
    freqs = np.linspace(f_lo, f_hi, n_freq)
    return 1.0 / freqs, pair_amplitudes(xm, rm - rm.mean(), freqs)


def _iso_figures(points: np.ndarray, leg: int, residual_points: np.ndarray) -> dict[str, Any]:
    """ISO 230-2 values (um) of the leg before and after compensation (procedures.reporting.iso230)."""
    from procedures.reporting import iso230

    before = iso230.evaluate_leg(points, leg)
    after = iso230.evaluate_leg(residual_points, leg)
    return {
        "before": dict(before.values),
        "after": dict(after.values),
        "not_computed": dict(before.reasons),
        "notes": list(before.notes),
    }


ISO_ROWS = tuple((k, f"{k}: {ISO_MEANINGS[k]}") for k in ("E", "M", "A", "B", "R"))




def model_is_normalised(model: LegErrorModel) -> bool:
    """Whether `model` was fitted to the error normalised to 20 degC (its `options.error_basis`,
    as `station fit` records it); a model that does not say was fitted to the raw error."""
    basis = (getattr(model, "options", None) or {}).get("error_basis")
    return bool(isinstance(basis, dict) and basis.get("normalised"))


def basis_is_raw(model: LegErrorModel | None, raw: bool = False, model_name: str = "the model") -> bool:
    """Whether an analysis compensating with `model` works on the raw error: the model's own basis
    (a normalised `model` with `raw` is refused, InputError naming `model_name`), else `raw`."""
    if model is None:
        return raw
    if model_is_normalised(model):
        if raw:
            raise InputError(f"{model_name} was fitted to the error normalised to 20 degC (its error_basis); "
                             "--raw would compare it with the raw error: drop --raw, or fit a raw model with "
                             "`station fit --raw` and use that one")
        return False
    return True


def report_basis(points: np.ndarray, station_config: dict | None, model: LegErrorModel | None = None,
                 raw: bool = False, model_name: str = "the model") -> tuple[np.ndarray, bool, dict[str, Any]]:
    """The points the report analyses, whether they are raw, and the basis as JSON
    ({"basis": "normalised"|"raw", "lines": [...], ...}, what `station fit` prints): the basis of
    `model` when given (a normalised model with `raw` is refused, InputError), else normalised to
    20 degC unless `raw`. `points` hold the raw recorded error_um."""
    from types import SimpleNamespace

    from procedures.metrology.thermal import error_basis

    from procedures.fit.dynamic import is_onthefly, static_points

    raw = basis_is_raw(model, raw, model_name)
    pts, lines, doc = error_basis(SimpleNamespace(points=points, station_config=station_config), raw)
    if len(pts) and is_onthefly(pts):  # on-the-fly readings: their static part, as the model was fitted to
        pts = static_points(pts)
    if model is not None and not isinstance((getattr(model, "options", None) or {}).get("error_basis"), dict):
        # fitted before models recorded their basis (or by fit() alone): raw; a model of
        # `station fit --raw` keeps error_basis's own "(--raw)" line, as the command printed it
        lines = ["error: raw, not normalised to 20 degC (the model records no error basis: fitted to the raw error)"]
    basis = "normalised" if doc.get("normalised") else "raw"
    return pts, basis == "raw", {"basis": basis, "lines": list(lines), **doc}


def make_report(points: np.ndarray, out_dir: str | os.PathLike, model: LegErrorModel | None = None, *,
                source_path: str = "", source_sha256: str = "", lead_mm: float | str | None = "auto",
                title: str = "", session_meta: dict[str, Any] | None = None, raw: bool = False,
                model_name: str = "") -> ReportResult:
    """Write the report files (module docstring) for a session's points into `out_dir`
    (created if missing). Without `model`, the default model is fitted to the points.
    `session_meta` ({"plan", "devices", "station_config", "attrs", "identity"} of the session) adds the
    ISO 230-2 test report (iso230-2.*). `points` hold the recorded (raw) error; the report works
    on the basis `report_basis` picks (normalised to 20 degC by default, `raw`, or the model's).
    Errors are measured minus commanded (um), positions mm."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a directory; choose another --out")
    src = source_path or "the session"
    station_config = (session_meta or {}).get("station_config") or None
    recorded = points
    points, is_raw, basis = report_basis(recorded, station_config, model, raw,
                                         model_name=model_name or "the model")
    by_leg = split_legs(points, source=src)
    fitted_here = model is None
    if model is None:
        model = fit(points, "default", lead_mm=lead_mm, source={"path": source_path, "sha256": source_sha256})
    legs = [leg for leg in by_leg if leg in model.legs]
    if not legs:
        raise InputError(f"{src}: the model has legs {list(model.legs)}, the session has legs {list(by_leg)}: "
                         "no leg in common; use the model fitted to this leg's recording")
    # built in a temporary folder, put into place when complete: Ctrl-C leaves no half report
    with atomic_folder(out) as work:
        same_source = fitted_here or (bool(source_sha256) and model.source.get("sha256") == source_sha256)

        resid: dict[int, np.ndarray] = {}
        for leg in legs:
            d = by_leg[leg]
            resid[leg] = d.error_um - model.predict_um(leg, d.position_mm, d.direction)

        n = len(legs)
        ncols = min(3, n)
        nrows = int(np.ceil(n / ncols))
        result = ReportResult(out)

        def grid(name: str, rows: int = nrows, cols: int = ncols, size=(5.0, 3.4)):
            fig, axes = plt.subplots(rows, cols, figsize=(size[0] * cols, size[1] * rows), squeeze=False)
            return fig, axes

        def save(fig, name: str) -> None:
            fig.tight_layout()
            fig.savefig(work / name, dpi=110)
            plt.close(fig)
            result.files.append(out / name)

        # errors with the model
        fig, axes = grid("errors")
        for ax, leg in zip(axes.flat, legs):
            d = by_leg[leg]
            lo, hi = model.legs[leg].stroke_mm
            xs = np.linspace(lo, hi, 1000)
            for sign, color, label in ((1, UP_COLOR, "approach +"), (-1, DOWN_COLOR, "approach -")):
                m = d.direction == sign
                ax.plot(d.position_mm[m], d.error_um[m], ".", ms=2, color=color, alpha=0.35, label=f"measured {label}")
                ax.plot(xs, model.predict_um(leg, xs, sign), "-", lw=1.2, color=color, label=f"model {label}")
            ax.set_title(f"leg {leg}: error and {model.method} model")
            ax.set_xlabel("position (mm)")
            ax.set_ylabel("error (um)")
            ax.grid(alpha=0.3)
        axes.flat[0].legend(fontsize=7)
        for ax in list(axes.flat)[n:]:
            ax.axis("off")
        save(fig, "errors.png")

        # residuals
        fig, axes = grid("residuals")
        for ax, leg in zip(axes.flat, legs):
            d = by_leg[leg]
            for sign, color in ((1, UP_COLOR), (-1, DOWN_COLOR)):
                m = d.direction == sign
                ax.plot(d.position_mm[m], resid[leg][m], ".", ms=2, color=color, alpha=0.4)
            ax.axhline(0.0, color="k", lw=0.8)
            ax.set_title(f"leg {leg}: residual (residual RMS {rms_about_mean_um(resid[leg]):.3f} um)")
            ax.set_xlabel("position (mm)")
            ax.set_ylabel("error - model (um)")
            ax.grid(alpha=0.3)
        for ax in list(axes.flat)[n:]:
            ax.axis("off")
        save(fig, "residuals.png")

        # histograms before / after (paper Figs. 7-8)
        fig, axes = plt.subplots(n, 2, figsize=(9.0, 2.6 * n), squeeze=False)
        for row, leg in enumerate(legs):
            d = by_leg[leg]
            # one x range per leg, so the narrowing is seen at a glance
            lo = min(float(d.error_um.min()), float(resid[leg].min()))
            hi = max(float(d.error_um.max()), float(resid[leg].max()))
            bins = np.linspace(lo, hi, 61) if hi > lo else 10
            for col, (values, what) in enumerate(((d.error_um, "error"), (resid[leg], "compensated error"))):
                ax = axes[row, col]
                ax.hist(values, bins=bins, color="0.55" if col == 0 else "tab:green", edgecolor="white", linewidth=0.3)
                ax.set_title(f"Histogram, {what} of leg {leg}", fontsize=9)
                ax.set_xlabel("error (um)")
                ax.set_ylabel("frequency")
        save(fig, "histograms.png")

        # residual spectrum
        fig, axes = grid("spectrum")
        for ax, leg in zip(axes.flat, legs):
            d = by_leg[leg]
            wl, amp = residual_spectrum(d, resid[leg])
            if wl.size:
                ax.semilogx(wl, amp, "-", lw=0.9, color="k")
            lead = lead_mm if isinstance(lead_mm, (int, float)) and lead_mm else _lead_of(model, leg)
            if lead:
                shortest = float(wl.min()) if wl.size else 0.0
                for h in (1, 2, 3):
                    if lead / h >= shortest:
                        ax.axvline(lead / h, color="tab:orange", ls="--", lw=0.9,
                                   label=f"screw lead {lead:g} mm and harmonics" if h == 1 else None)
                ax.legend(fontsize=7)
            ax.set_title(f"leg {leg}: residual spectrum")
            ax.set_xlabel("wavelength (mm)")
            ax.set_ylabel("amplitude (um)")
            ax.grid(alpha=0.3, which="both")
        for ax in list(axes.flat)[n:]:
            ax.axis("off")
        save(fig, "spectrum.png")

        # summary
        rows = []
        for leg in legs:
            d = by_leg[leg]
            f = model.legs[leg]
            noise = estimate_noise_floor(d)
            up = d.error_um[d.direction == 1]
            down = d.error_um[d.direction == -1]
            before_range = range_um(d.error_um)
            residual_range = range_um(resid[leg])
            residual_points = points[points["leg"] == leg].copy()
            # the same rows split_legs kept (finite target and error), in the same order
            residual_points = residual_points[np.isfinite(residual_points["target_mm"]) & np.isfinite(residual_points["error_um"])]
            residual_points["error_um"] = resid[leg]
            row = {
                "leg": leg,
                "points": d.n_points,
                "passes": d.n_passes,
                "cycles": d.n_cycles,
                "stroke_mm": list(f.stroke_mm),
                "range_before_um": before_range,
                "residual_range_um": residual_range,
                "residual_range_reduction_pct": reduction_pct(before_range, residual_range),
                "rms_before_um": rms_about_mean_um(d.error_um),
                "residual_rms_um": rms_about_mean_um(resid[leg]),
                "mean_abs_before_um": float(np.mean(np.abs(d.error_um))),
                "residual_mean_abs_um": float(np.mean(np.abs(resid[leg]))),
                "reversal_um": float(down.mean() - up.mean()) if up.size and down.size else None,
                "noise_floor_um": noise.noise_floor_um,
                "model_terms": f.describe(),
                "model_heldout_rms_um": f.stats.heldout_rms_um,
                "model_noise_floor_um": f.stats.noise_floor_um,
                "model_heldout_ratio": f.stats.heldout_ratio,
                "iso230_2": _iso_figures(points, leg, residual_points),
            }
            rows.append(row)
        summary = {
            "source": {"path": source_path, "sha256": source_sha256},
            "model": {"method": model.method, "source": model.source, "fitted_to_this_session": same_source},
            "residuals": "in-sample (model fitted to this session)" if same_source else "out-of-sample (model from another recording)",
            "error_basis": basis,
            "legs": rows,
        }
        result.summary = json_safe(summary)
        write_text_atomic(work / "summary.json", json.dumps(result.summary, indent=2, sort_keys=True) + "\n")
        result.files.append(out / "summary.json")
        write_text_atomic(work / "summary.md", _markdown(result.summary, title or f"Report: {source_path or 'session'}"))
        result.files.append(out / "summary.md")
        if session_meta is not None:
            from procedures.reporting import iso230_report

            meta = {k: session_meta.get(k) or {} for k in ("plan", "devices", "station_config", "attrs", "identity",
                                                           "tolerances")}
            meta["stage"] = session_meta.get("stage")  # None: from the plan kind
            # the recorded points: the ISO report normalises them itself (unless raw), on the same basis
            result.iso230, paths = iso230_report.write(recorded, work, source={"path": source_path, "sha256": source_sha256},
                                                       raw=is_raw, **meta)
            result.files.extend(out / p.name for p in paths)
    return result


def _f(v: Any, spec: str = ".3f") -> str:
    return "n/a" if v is None else format(v, spec)


def _markdown(s: dict[str, Any], title: str) -> str:
    lines = [f"# {title}", ""]
    src = s["source"]
    lines.append(f"Recording: `{src['path'] or 'n/a'}` (sha256 `{(src['sha256'] or 'n/a')[:16]}`)  ")
    m = s["model"]
    lines.append(f"Model: {m['method']} (from `{m['source'].get('path') or 'n/a'}`); residuals are {s['residuals']}.")
    lines.append("")
    basis = s.get("error_basis") or {}
    lines.append(f"Error basis: **{basis.get('basis', 'raw')}** (fit, plots, figures and ISO 230-2 alike; "
                 "docs/metrology.md):")
    lines.append("")
    lines += [f"    {line}" for line in basis.get("lines") or []]
    lines.append("")
    lines.append("| leg | points | cycles | range before (um) | residual range (um) | residual range reduction | "
                 "RMS before (um) | residual RMS (um) | reversal (um) | noise floor (um) | model held-out RMS (um) | "
                 "model held-out ratio |")
    lines.append("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in s["legs"]:
        lines.append(
            f"| {r['leg']} | {r['points']} | {r['cycles']} | {_f(r['range_before_um'])} | {_f(r['residual_range_um'])} | "
            f"{_f(r['residual_range_reduction_pct'], '.1f')} % | {_f(r['rms_before_um'])} | {_f(r['residual_rms_um'])} | "
            f"{_f(r['reversal_um'])} | {_f(r['noise_floor_um'])} | {_f(r['model_heldout_rms_um'])} | "
            f"{_f(r['model_heldout_ratio'], '.2f')} |"
        )
    lines.append("")
    lines.append("Range before: max - min of the measured errors; residual: error minus model on this session's points "
                 f"({s['residuals']}); residual range: its max - min; RMS before and residual RMS: about the mean; "
                 "reversal: mean error approaching downwards minus upwards; noise floor: pooled pass-to-pass scatter "
                 "at the same target and direction; model held-out RMS and ratio: from the model's own cross-validation "
                 "(each cycle scored by a model fitted without it), as `station fit` prints them (see docs/figures.md).")
    lines.append("")
    lines.append("ISO 230-2 (um), before -> after compensation:")
    lines.append("")
    lines.append("| leg | " + " | ".join(label for _, label in ISO_ROWS) + " |")
    lines.append("|---:|" + "---:|" * len(ISO_ROWS))
    for r in s["legs"]:
        iso = r["iso230_2"]
        cells = [f"{_f(iso['before'].get(k))} -> {_f(iso['after'].get(k))}" for k, _ in ISO_ROWS]
        lines.append(f"| {r['leg']} | " + " | ".join(cells) + " |")
    for r in s["legs"]:
        for note in r["iso230_2"]["notes"]:
            lines.append(f"- leg {r['leg']}: {note}")
    lines.append("")
    lines.append("Terms:")
    for r in s["legs"]:
        lines.append(f"- leg {r['leg']}: {r['model_terms']}")
    lines.append("")
    lines.append("Plots: errors.png, residuals.png, histograms.png, spectrum.png")
    return "\n".join(lines) + "\n"
