"""Figures: what applying the default (normalised to 20 degC) model of the committed sample to
its RAW recorded error did to the platform experiment (before the fix), against the error on the
model's own basis (now). Prints the leg-error figures of `station platform MODEL.json` (mean of
passes, 2000 poses, seed 0). Run: .venv/bin/python bench/bench_platform_basis.py"""

from pathlib import Path

from procedures.fit import fit
from procedures.metrology.thermal import normalise_session
from procedures.platform.experiment import RecordedLegErrors, Workspace, run_measurements
from procedures.platform.geometry import default_geometry
from procedures.io.recording.reader import read_session

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "calibration-6legs.h5"

session = read_session(SAMPLE)
norm = normalise_session(session.points, session.station_config)
model = fit(norm.points, "default")  # what `station fit` makes by default
for name, points in (("recording normalised (model's basis, now)", norm.points),
                     ("recording raw (mismatch, before)", session.points)):
    errors = RecordedLegErrors(points, predicted_um=model.predict_um, source=name, measurement="mean")
    _, s = run_measurements(default_geometry(), errors, poses=2000, seed=0, workspace=Workspace())
    legs = s["legs"]["all"]
    print(f"{name}: leg range original {legs['range_original']:.3f} um, compensated {legs['range_compensated']:.3f} um "
          f"(reduction {legs['range_reduction_pct']:.1f} %), mean |compensated| {legs['mean_abs_compensated']:.3f} um")
