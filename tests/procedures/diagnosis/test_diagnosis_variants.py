"""The variants' self-check (issue 25): sessions made with the plant's variant physics, withheld
from the twin: the right effect and variant named, parameters within 15 %, the held-out gap within
25 % of the oracle's, nothing named on clean legs.

A bounded number of seeds per physics by default; STATION_DIAG_VARIANT_SEEDS=250 runs the long
check (docs/diagnosis.md gives its figures; `station diagnose --self-check --variants --seeds 250`
is the same from the command line)."""

from __future__ import annotations

import os

import pytest

from procedures.diagnosis import DiagnosisSettings
from procedures.diagnosis.selfcheck import (VARIANT_GAP_TOLERANCE, VARIANT_PARAM_TOLERANCE, evaluate_trial,
                                            format_by_physics, run_self_check, summarise_by_physics)
from procedures.synthetic import VARIANT_PHYSICS, variant_trial

SEEDS = int(os.environ.get("STATION_DIAG_VARIANT_SEEDS", "10"))


@pytest.fixture(scope="module", params=VARIANT_PHYSICS)  # issue 35's situations: test_diagnosis_situations.py
def physics_result(request):
    res = run_self_check([variant_trial(s, request.param) for s in range(SEEDS)], DiagnosisSettings(), None,
                         VARIANT_PARAM_TOLERANCE, VARIANT_GAP_TOLERANCE)
    return request.param, res


def test_each_physics_is_named_with_its_variant_and_parameters(physics_result):
    name, res = physics_result
    summary = summarise_by_physics(res["trials"])[name]
    print(format_by_physics({name: summary}, VARIANT_PARAM_TOLERANCE, VARIANT_GAP_TOLERANCE))
    assert summary["sessions"] == SEEDS
    assert summary["name_and_variant_right"] == SEEDS
    assert summary["named_on_clean"] == 0
    for p, v in summary["params"].items():
        assert v["max_pct"] <= 100 * VARIANT_PARAM_TOLERANCE, p
    assert summary["gap_ok"] == summary["gap_checked"] == SEEDS


def test_a_plain_effect_named_as_a_variant_fails_the_check():
    t = variant_trial(0, "windup")
    (leg,) = t.truth
    plain = {leg: {"backlash": {"reversal_um": 1.0}}}  # claim: a plain reversal
    from dataclasses import replace

    r = evaluate_trial(replace(t, truth=plain), DiagnosisSettings())
    assert not r["ok"] and r["legs"][0]["wrong_variant"] == ["backlash: windup instead of plain"]
