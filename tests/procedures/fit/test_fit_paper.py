"""The seed paper's method (Algorithm 1, Eqs. 2-7): exact on band-limited data, refuses what it
cannot handle, and shows the weaknesses the default model fixes."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.synthetic import synth_session
from procedures.vocabulary import InputError
from procedures.fit import fit
from procedures.acquisition.plans import irregular_targets
from procedures.io.recording.schema import POINT_DTYPE


def points_from(targets_mm, error_fn, passes=2, leg=1):
    """Points of `passes` one-direction passes (alternating up/down) with error_fn(x, direction)."""
    targets = np.asarray(targets_mm, dtype=float)
    rows = []
    for run in range(1, passes + 1):
        d = 1 if run % 2 else -1
        seq = targets if d == 1 else targets[::-1]
        for x in seq:
            rows.append((len(rows), leg, run, d, x, x, x, x, error_fn(x, d), float(len(rows)),
                         20.0, 1013.25, 45.0, 20.0, 0.0, 90.0, 0, np.nan))
    return np.array(rows, dtype=POINT_DTYPE)


TERMS = ((3, 0.8, 0.3), (11, 0.25, -1.2), (40, 0.05, 2.0))  # (k cycles per sweep, amplitude um, phase rad)


def cosines(n, x0, spacing, mean=0.4):
    def f(x, d=1):
        t = (x - x0) / (n * spacing)  # Eq. 7
        return mean + sum(a * np.cos(2 * np.pi * k * t + p) for k, a, p in TERMS)

    return f


@pytest.mark.parametrize("n", [361, 100])  # odd (the paper's 361) and even N
def test_reproduces_a_sum_of_cosines_exactly(n):
    spacing = 0.5
    targets = -90.0 + spacing * np.arange(n)
    f = cosines(n, targets[0], spacing)
    model = fit(points_from(targets, f), "paper", n_params=len(TERMS))
    leg = model.legs[1]
    assert sorted(leg.k.tolist()) == sorted(k for k, _, _ in TERMS)
    by_k = {int(k): (a, p) for k, a, p in zip(leg.k, leg.amplitude_um, leg.phase_rad)}
    for k, a, p in TERMS:
        # amplitude normalised 2|F_k|/N: the stored value is the cosine's own amplitude
        assert by_k[k][0] == pytest.approx(a, abs=1e-12)
        assert np.angle(np.exp(1j * (by_k[k][1] - p))) == pytest.approx(0.0, abs=1e-9)
    assert leg.mean_um == pytest.approx(0.4, abs=1e-12)
    # at the targets and between them (the sum is band-limited, so Eq. 6 is exact everywhere)
    x = np.concatenate([targets, targets[:-1] + 0.2])
    np.testing.assert_allclose(model.predict_um(1, x, 1), f(x), atol=1e-10)
    # the paper's default of 100 terms keeps the three (and near-zero others)
    model100 = fit(points_from(targets, f), "paper")
    np.testing.assert_allclose(model100.predict_um(1, targets, -1), f(targets), atol=1e-10)


def test_keeps_the_largest_amplitudes():
    n, spacing = 121, 1.0
    targets = -60.0 + spacing * np.arange(n)
    model = fit(points_from(targets, cosines(n, targets[0], spacing)), "paper", n_params=2)
    assert sorted(model.legs[1].k.tolist()) == [3, 11]


def test_pools_directions_and_ignores_them():
    targets = np.linspace(-90, 90, 91)
    model = fit(points_from(targets, lambda x, d: 0.01 * x - 0.5 * d, passes=4), "paper")
    np.testing.assert_allclose(model.predict_um(1, targets, 1), model.predict_um(1, targets, -1))
    # the pooled mean has no reversal in it: the +/-0.5 um of each direction stays in the residual
    np.testing.assert_allclose(model.predict_um(1, targets, 1), 0.01 * targets, atol=1e-9)


def test_refuses_irregular_spacing():
    targets = irregular_targets(-90.0, 90.0, 21, seed=3)
    with pytest.raises(InputError) as err:
        fit(points_from(targets, lambda x, d: 0.0), "paper")
    text = str(err.value)
    assert "leg 1" in text and "uniformly spaced" in text and "--method default" in text


def test_trend_rings_at_the_stroke_ends():
    # a pure lead slope is not periodic over the sweep: truncating its spectrum (M = 100 of 180)
    # leaves Gibbs ringing, worst at the ends
    targets = np.linspace(-90, 90, 361)
    pts = points_from(targets, lambda x, d: 0.009 * x, passes=2)
    model = fit(pts, "paper")
    resid = 0.009 * targets - model.predict_um(1, targets, 1)
    assert np.abs(resid[:3]).max() > 5 * np.abs(resid[150:210]).max()
    assert np.abs(resid[:3]).max() > 0.05  # tens of nanometres, on a 1.6 um slope


def test_heldout_figures_leave_backlash_in():
    cfg = PlantConfig().only("backlash", "lead", "noise")
    pts = synth_session({1: cfg}, np.linspace(-90, 90, 61), cycles=4, seed=2)
    s = fit(pts, "paper").legs[1].stats
    assert s.folds == 4 and s.n_cycles == 4
    # half the reversal is left on every point: RMS ~ reversal / 2 = 0.5 um >> noise 0.03 um
    assert s.heldout_rms_um == pytest.approx(cfg.reversal_um / 2, rel=0.1)
    assert s.heldout_ratio > 5
