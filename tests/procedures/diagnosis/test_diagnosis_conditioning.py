"""Short recordings: the twin and every fold fit stay well-conditioned (rank-limited solves, the
twin's size capped where its columns become nearly dependent), so the held-out gap after the
named effects stays near the gap left by the true effects (issue 25 item 6)."""

from __future__ import annotations

import numpy as np
import pytest

from procedures.diagnosis import DiagnosisSettings
from procedures.diagnosis.selfcheck import evaluate_trial
from procedures.diagnosis.significance import condition_number, solve_gram
from procedures.synthetic import selfcheck_trial


def test_nearly_collinear_columns_give_a_bounded_solution():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(200, 3))
    x = np.column_stack([x, x[:, 0] + 1e-9 * rng.normal(size=200)])  # column 4 copies column 1
    y = x[:, 0] + 0.5 * x[:, 1]
    g = x.T @ x
    assert condition_number(g) > 1e6
    c = solve_gram(g, x.T @ y)
    assert np.abs(c).max() < 10  # the minimum-norm split of the copied column, not +-1e7
    assert np.allclose(x @ c, y, atol=1e-6)


def _short_load_trials(n):
    """Even seeds (twin fitted on the session) whose 4-cycle, 61-target session carries a load effect."""
    out, seed = [], 0
    while len(out) < n:
        t = selfcheck_trial(seed, n_targets=61, cycles=4)
        if "load" in t.label:
            out.append(t)
        seed += 2
    return out


@pytest.fixture(scope="module")
def short_results():
    return [evaluate_trial(t, DiagnosisSettings()) for t in _short_load_trials(6)]


def test_short_recordings_with_a_load_effect_keep_an_honest_gap(short_results):
    for r in short_results:
        for leg in r["legs"]:
            assert not leg["missed"] and not leg["wrong"], (r["seed"], leg)
            assert leg["gap_ratio"] <= 1.25, (r["seed"], leg["leg"], leg["gap_ratio"])


def test_the_twin_reports_its_condition_number():
    from procedures.diagnosis import diagnose

    t = _short_load_trials(4)[-1]
    for leg in diagnose(t.points)["legs"].values():
        assert 1 <= leg["twin"]["condition_number"] < 1e6
