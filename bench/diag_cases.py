"""Bench: the cases of issue 25's "Why", each on a session made for it, diagnosed by the code
tree given (so the same sessions can be diagnosed before and after a change).

    python bench/diag_cases.py make DIR            # this tree's plant makes the sessions (npz)
    python bench/diag_cases.py diagnose DIR [TREE] # TREE's diagnosis (default: this tree) prints one line per case

The sessions are made once, with this tree's plant (whose variant physics an older tree lacks);
an external twin is stored as its prediction at the targets, a reference twin as its points.
The oracle (the twin plus the true effect with its true size, held-out RMS) is computed at make
time with this tree's code. Prints figures; not a test.
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]
BASE = frozenset({"lead", "longwave", "wobble", "noise", "run_offset"})


def _make(out: Path) -> None:
    sys.path.insert(0, str(HERE))
    from drivers.plant.leg import default_leg_configs, systematic_error_um
    from procedures.diagnosis import DiagnosisSettings
    from procedures.diagnosis.selfcheck import Trial, oracle_rms_um
    from procedures.synthetic import selfcheck_trial
    from procedures.synthetic import synth_session
    from procedures.diagnosis.twin import plant_twin

    out.mkdir(parents=True, exist_ok=True)
    meta = {}
    targets = np.linspace(-90, 90, 91)
    leg = replace(default_leg_configs(3, 1)[0], enabled=BASE, drift_um_per_h=0.0)
    swing = dict(initial_temp_c=19.0, ambient_swing_k=1.5, ambient_period_s=3600.0, tau_s=900.0)

    def save(name, pts, cfg=None, eff=None, twin_cfg=None, truth=None, ref=None, true_um=None):
        arrays = {"points": pts}
        if twin_cfg is not None:
            arrays["twin_x"] = np.unique(pts["target_mm"])
            arrays["twin_um"] = systematic_error_um(twin_cfg, arrays["twin_x"], 0.0, twin_cfg.temp_ref_c, 0.0, 0.0)
        if ref is not None:
            arrays["ref"] = ref
        oracle = None
        if true_um is None and cfg is not None and eff:
            true_um = sum(systematic_error_um(cfg.only(e), pts["target_mm"], pts["direction"], pts["material_temp_c"],
                                              pts["load_n"], pts["time_s"], _since(pts) + 2.0) for e in eff)
        if true_um is not None:
            twin = plant_twin({1: twin_cfg}, "plant") if twin_cfg is not None else None
            oracle = oracle_rms_um(Trial(0, pts, twin, {}, true_um), DiagnosisSettings()).get(int(pts["leg"][0]))
        np.savez(out / f"{name}.npz", **arrays)
        meta[name] = {"truth": truth or {}, "oracle_after_um": oracle}

    # a reversal that grows as the leg warms, with thermal expansion
    cfg = replace(leg, enabled=BASE | {"backlash", "thermal"}, reversal_um=1.0, reversal_um_per_k=0.4, **swing)
    save("reversal_grows_with_temperature", synth_session({1: cfg}, targets, 5, seed=11, dwell_s=4.0), cfg,
         ("backlash", "thermal"), truth={"reversal_um_per_k": 0.4, "expansion_ppm_per_k": cfg.expansion_ppm_per_k})
    # lost motion winding up over 6 mm after each reversal
    cfg = replace(leg, enabled=BASE | {"backlash"}, reversal_um=2.0, windup_mm=6.0)
    save("lost_motion_windup", synth_session({1: cfg}, targets, 5, seed=12, dwell_s=4.0), cfg, ("backlash",),
         truth={"windup_mm": 6.0})
    # nut wear: the reversal 1.5 um larger around -30 mm
    cfg = replace(leg, enabled=BASE | {"backlash"}, reversal_um=1.0, reversal_wear_um=1.5, reversal_wear_centre_mm=-30.0,
                  reversal_wear_half_width_mm=150.0)
    xs = np.linspace(-90, 90, 361)
    rev = 1.0 + 1.5 * np.maximum(0, 1 - ((xs + 30) / 150) ** 2)
    save("nut_wear", synth_session({1: cfg}, targets, 5, seed=13, dwell_s=4.0), cfg, ("backlash",),
         truth={"reversal_change_um": float(np.ptp(rev)), "reversal_max_at_mm": float(xs[np.argmax(rev)])})
    # thermal expansion with a gradient along the screw, a leg warming
    cfg = replace(leg, enabled=BASE | {"thermal"}, initial_temp_c=18.0, ambient_temp_c=22.0, tau_s=1500.0,
                  expansion_gradient_ppm_per_k_per_m=300.0)
    save("thermal_gradient", synth_session({1: cfg}, targets, 5, seed=14, dwell_s=4.0), cfg, ("thermal",),
         truth={"expansion_gradient_ppm_per_k_per_m": 300.0})
    # a 1.5625 mm gearbox term sampled every 1.25 mm, against the plant without it
    real = replace(leg, longwave=leg.longwave + ((1.5625, 0.5, 0.3),))
    pts = synth_session({1: real}, np.arange(-90, 90.001, 1.25), 5, seed=15, dwell_s=4.0)
    save("gearbox_alias", pts, twin_cfg=leg, truth={"true_wavelength_mm": 1.5625})
    # a reference twin recorded 3 K warmer
    cfg = replace(leg, enabled=BASE | {"thermal"}, heating_k_per_m=0.0)
    ref = synth_session({1: replace(cfg, initial_temp_c=23.0, ambient_temp_c=23.0)}, targets, 5, seed=16, dwell_s=4.0)
    save("reference_3k_warmer", synth_session({1: cfg}, targets, 5, seed=17, dwell_s=4.0), ref=ref,
         truth={"scale_expected_ppm": -3.0 * cfg.expansion_ppm_per_k})
    # warm-up: the cold first pass
    cfg = replace(leg, enabled=BASE | {"thermal", "backlash"}, initial_temp_c=18.0, ambient_temp_c=20.5, tau_s=400.0)
    save("warm_up_cold_first_pass", synth_session({1: cfg}, targets, 5, seed=5, dwell_s=4.0), truth={})
    # a short recording: 4 cycles, 61 targets, a load effect (and a reversal)
    t = selfcheck_trial(22, n_targets=61, cycles=4)
    save("short_recording_with_load", t.points, true_um=t.true_effect_um, truth={"effects": t.label})
    # on-the-fly, passes at 5, 10 and 20 mm/s (read through the interchange CSV)
    cfg = replace(leg, enabled=BASE | {"backlash"})
    pts = synth_session({1: cfg}, targets, 6, seed=18, dwell_s=0.5)
    v = np.array([(5.0, 10.0, 20.0)[(r - 1) // 2 % 3] for r in pts["run"]]) * pts["direction"]
    pts["speed_mm_s"] = v
    pts["error_um"] += -np.where(v > 0, cfg.dynamic_lag_up_s, cfg.dynamic_lag_down_s) * v * 1000.0
    save("on_the_fly_speed_csv", pts, truth={"lag_up_ms": 1e3 * cfg.dynamic_lag_up_s,
                                             "lag_down_ms": 1e3 * cfg.dynamic_lag_down_s})
    (out / "meta.json").write_text(json.dumps(meta, indent=1))
    print(f"{len(meta)} sessions in {out}")


def _since(pts):
    out = np.zeros(pts.size)
    for r in np.unique(pts["run"]):
        sel = pts["run"] == r
        out[sel] = np.abs(pts["target_mm"][sel] - pts["target_mm"][sel][0])
    return out


def _fmt(v):
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _diagnose(src: Path, tree: Path) -> None:
    sys.path.insert(0, str(tree))
    from procedures.diagnosis import diagnose
    from procedures.diagnosis.twin import ExternalTwin
    try:
        from procedures.diagnosis.reference_twin import twin_from_recording
    except ImportError:  # a tree from before the reference twin had a module of its own
        from procedures.diagnosis.twin import twin_from_recording

    meta = json.loads((src / "meta.json").read_text())
    for name, m in meta.items():
        z = np.load(src / f"{name}.npz")
        pts = z["points"]
        twin = None
        if "twin_x" in z:
            tx, tu = z["twin_x"], z["twin_um"]
            twin = ExternalTwin(predict=lambda leg, x, d, tx=tx, tu=tu: np.interp(x, tx, tu), kind="sim",
                                description="plant")
        if "ref" in z:
            twin = twin_from_recording(z["ref"], "reference")
        if name == "on_the_fly_speed_csv":
            pts = _through_csv(pts, src)
            if pts is None:
                continue
        rep = diagnose(pts, twin)
        leg = next(iter(rep["legs"].values()))
        found = []
        for f in rep["findings"]:
            keys = [k for k in f["parameters"] if k in m["truth"] or k in ("reversal_um", "expansion_ppm_per_k",
                                                                            "wavelength_mm", "scale_ppm")]
            ps = ", ".join(f"{k}={_fmt(f['parameters'][k])}" for k in keys)
            extra = "".join(f" [{f[k]['note'][:150]}...]" for k in ("sampling", "temperature_difference") if f.get(k))
            found.append(f"{f['effect']}{'/' + f['variant'] if f.get('variant') else ''}({ps}){extra}")
        c = leg.get("combined") or {}
        shrink = c.get("shrink_pct")
        oracle = m["oracle_after_um"]
        line = f"{name}: named {'; '.join(found) or 'nothing'}"
        if shrink is not None and c.get("heldout_rms_before_um"):
            line += f" | held-out after {c['heldout_rms_after_um']:.3g} um ({shrink:.0f} % shrink)"
            if oracle:
                line += (f", true effects' {oracle:.3g} um ({100 * (1 - oracle / c['heldout_rms_before_um']):.0f} %), "
                         f"ratio {c['heldout_rms_after_um'] / oracle:.2f}")
        tw = leg.get("twin", {})
        if tw.get("sinusoids") is not None:
            line += f" | twin {tw['sinusoids']} sinusoids"
        if leg.get("outlier_passes"):
            line += " | outlier passes " + ", ".join(f"run {p['run']}" for p in leg["outlier_passes"])
        if leg.get("passes_explained_by_temperature"):
            line += " | explained by temperature: " + ", ".join(f"run {p['run']}" for p in leg["passes_explained_by_temperature"])
        if (leg.get("unexplained") or {}).get("note"):
            line += f" | UNEXPLAINED: {leg['unexplained']['note'][:160]}"
        line += f" | words: {leg['dominant'][:110]}"
        print(line)
        print(f"    truth: {m['truth']}")


def _through_csv(pts, src: Path):
    """The on-the-fly session written as an interchange CSV and imported (speed_mm_s column)."""
    from procedures.io.csv_io import import_csv
    from procedures.vocabulary import InputError
    from procedures.io.recording.reader import read_session

    csv_path, h5 = src / "otf.csv", src / "otf.h5"
    h5.unlink(missing_ok=True)
    cols = ("target_mm", "error_um", "time_s", "speed_mm_s")
    rows = [f"{p['leg']},{p['run']},{p['direction']:+d}," + ",".join(repr(float(p[k])) for k in cols) for p in pts]
    csv_path.write_text("leg,run,direction," + ",".join(cols) + "\n" + "\n".join(rows) + "\n")
    try:
        import_csv(csv_path, h5)
    except InputError as exc:
        print(f"on_the_fly_speed_csv: import refused: {str(exc)[:200]}")
        return None
    return read_session(h5).points


if __name__ == "__main__":
    if len(sys.argv) < 3 or sys.argv[1] not in ("make", "diagnose"):
        print(__doc__)
        sys.exit(2)
    if sys.argv[1] == "make":
        _make(Path(sys.argv[2]))
    else:
        _diagnose(Path(sys.argv[2]), Path(sys.argv[3]) if len(sys.argv) > 3 else HERE)
