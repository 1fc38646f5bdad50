"""An ABOVE verification says what the technician does next (issue 22, item 7): a calibration
whose targets are too far apart to resolve the screw is to be repeated with targets every 1 mm;
otherwise diagnose and calibrate again. A PASS says nothing more."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from procedures.io.recording.reader import read_session
from procedures.compensation.verify import SCREW_RESOLVING_SPACING_MM, format_report, verify

SAMPLE = Path(__file__).resolve().parents[3] / "recordings" / "calibration-6legs.h5"


def _coarse(points: np.ndarray, every: int) -> np.ndarray:
    """The points at every `every`-th distinct target: a calibration with fewer, wider-spaced targets."""
    targets = np.unique(points["target_mm"])[::every]
    return points[np.isin(points["target_mm"], targets)]


def test_above_after_a_coarse_calibration_asks_for_targets_every_mm():
    pts = read_session(SAMPLE).points
    before = _coarse(pts, 16)
    r = verify(pts, before, [2])[2]
    assert r.passed is False and r.before.target_spacing_mm > SCREW_RESOLVING_SPACING_MM
    text = format_report({2: r})
    nxt = [line for line in text.splitlines() if line.strip().startswith("next:")]
    assert nxt == [f"  next: the calibration's targets are {r.before.target_spacing_mm:.3g} mm apart, too far apart "
                   "to resolve the screw's once-per-turn error, so the table cannot correct it: calibrate again with "
                   "targets every 1 mm (`station sweep --step 1 --cycles 8 --legs 2 ...`), fit, make the table (its step follows "
                   "the recording), push it and verify again (README, calibration)"]


def test_above_after_a_fine_calibration_points_to_diagnose():
    pts = read_session(SAMPLE).points
    r = verify(pts, pts, [1])[1]
    assert r.passed is False and r.before.target_spacing_mm <= SCREW_RESOLVING_SPACING_MM
    assert "  next: `station diagnose` on the calibration names what the table leaves" in format_report({1: r})


def test_a_pass_has_no_next_step():
    pts = read_session(SAMPLE).points
    r = verify(pts, pts, [1])[1]
    passed = replace(r, after=replace(r.after, rms_um=r.after.noise_floor_um))  # ratio 1.0
    assert passed.passed and "next:" not in format_report({1: passed})


def test_just_above_from_few_cycles_asks_for_a_longer_verification_first():
    """A few-cycle verification's ratio scatters (its floor and residual rest on a few pass
    offsets): just above the limit, the next step is a longer verification, not a recalibration."""
    pts = read_session(SAMPLE).points
    r = verify(pts, pts, [1])[1]
    near = replace(r, after=replace(r.after, rms_um=1.15 * r.after.noise_floor_um))
    assert near.passed is False and near.after.n_cycles < 10
    nxt = [line for line in format_report({1: near}).splitlines() if line.strip().startswith("next:")]
    assert len(nxt) == 1 and "verify again with more cycles (`station verify --leg 1 --cycles 20 ...`)" in nxt[0]
    assert "if it stays above: `station diagnose`" in nxt[0]
    # far above, or from a long verification: the table itself is in question
    far = replace(r, after=replace(r.after, rms_um=1.5 * r.after.noise_floor_um))
    long = replace(near, after=replace(near.after, n_cycles=20))
    for x in (far, long):
        assert "  next: `station diagnose` on the calibration names what the table leaves" in format_report({1: x})
