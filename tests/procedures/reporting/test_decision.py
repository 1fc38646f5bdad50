"""ISO 14253-1 decisions (procedures.reporting.decision) at the boundaries and the decisions carried by
the ISO 230-2 report of a synthetic session (the tolerances of the station config:
tests/station/services/test_config_for_procedures.py)."""

from __future__ import annotations

import pytest

from procedures.reporting import decision as dec

BUDGET = [{"source": "laser", "u_um": 0.3}, {"source": "repeatability", "u_um": 0.4},
          {"source": "repeatability", "u_um": 0.3}]


@pytest.mark.parametrize("value, U, limit, outcome", [
    (5.0, 1.0, 6.0, dec.CONFORMS),        # value + U exactly at the limit: conforms
    (5.0, 1.0 + 1e-6, 6.0, dec.UNDECIDED),  # a hair more U: the interval reaches over the limit
    (4.9, 1.1, 6.0, dec.CONFORMS),        # 4.9 + 1.1 = 6.000000000000001 in binary: still at the limit
    (7.0, 1.0, 6.0, dec.UNDECIDED),       # value - U exactly at the limit: not proven outside
    (7.0, 1.0 - 1e-6, 6.0, dec.NOT_CONFORM),
    (6.0, 0.0, 6.0, dec.CONFORMS),        # zero U: the value itself decides
    (6.0 + 1e-6, 0.0, 6.0, dec.NOT_CONFORM),
    (0.5, 7.0, 6.0, dec.UNDECIDED),       # U larger than the tolerance: never conforms
    (20.0, 7.0, 6.0, dec.NOT_CONFORM),    # ... but a value far out still does not conform
])
def test_decide_at_the_boundaries(value, U, limit, outcome):
    d = dec.decide("E", value, U, limit, BUDGET)
    assert d.outcome == outcome, d.reason
    assert d.limit_um == limit and d.value_um == value and d.U_um == U


def test_undecided_names_the_dominant_contribution_and_a_too_large_U():
    d = dec.decide("E", 5.5, 1.0, 6.0, BUDGET)
    assert d.outcome == dec.UNDECIDED
    # repeatability: 0.4^2 + 0.3^2 = 0.25 of 0.34 total -> 74 %
    assert "repeatability (74 % of u^2)" in d.reason and d.dominant.startswith("repeatability")
    big = dec.decide("E", 0.5, 7.0, 6.0, BUDGET)
    assert "exceeds the tolerance itself" in big.reason


def test_no_tolerance_and_not_computed():
    assert dec.decide("E", 1.0, 0.1, None).outcome == dec.NO_TOLERANCE
    assert dec.decide("E", None, None, 6.0).outcome == dec.NOT_COMPUTED
    assert dec.decide("E", 1.0, None, 6.0).outcome == dec.UNDECIDED


def test_overall_verdict():
    c = dec.decide("E", 1, 0.1, 6)
    n = dec.decide("B", 9, 0.1, 6)
    u = dec.decide("R", 5.95, 0.1, 6)
    none = dec.decide("M", 1, 0.1, None)
    assert dec.overall([c, none]) == dec.CONFORMS
    assert dec.overall([c, u]) == dec.UNDECIDED
    assert dec.overall([c, u, n]) == dec.NOT_CONFORM
    assert dec.overall([none]) == dec.NO_TOLERANCE


def _leg_report(value, U, leg_type):
    return {"identification": {"leg_identity": {"1": {"leg_type": leg_type}}},
            "legs": {"1": {"values": {"E": {"value_um": value, "U_um": U}, "B": {"value_um": 1.0, "U_um": 0.2}},
                           "budget": {"values": {"E": {"contributions": BUDGET}}}}}}


def test_decide_report_uses_the_leg_type_of_the_identity():
    tol = {"HX300": dec.Tolerance("HX300", {"E": 6.0, "B": 2.0}, {"E": 3.0, "B": 2.0}, "x [tolerances.HX300]")}
    found = dec.decide_report(_leg_report(4.0, 0.5, "HX300"), tol, "as_found")["1"]
    assert found["overall"] == dec.CONFORMS and set(found["values"]) == {"E", "B"}
    left = dec.decide_report(_leg_report(4.0, 0.5, "HX300"), tol, "as_left")["1"]
    assert left["overall"] == dec.NOT_CONFORM and left["values"]["E"]["limit_um"] == 3.0
    untyped = dec.decide_report(_leg_report(4.0, 0.5, "not stated"), tol, "as_found")["1"]
    assert untyped["overall"] == dec.NO_TOLERANCE and "no leg type" in untyped["reason"]
    other = dec.decide_report(_leg_report(4.0, 0.5, "HX500"), tol, "as_found")["1"]
    assert other["overall"] == dec.NO_TOLERANCE and "[tolerances.HX500]" in other["reason"]
