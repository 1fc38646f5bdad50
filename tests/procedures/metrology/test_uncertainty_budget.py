"""The uncertainty budget's structure (procedures.metrology.uncertainty): every contribution
listed with input u, sensitivity and contribution; the scale terms correlated across targets
(through the span between extremes) and absent from B; table entries growing with |P|."""

from __future__ import annotations

import json
import math

import pytest

from drivers.plant.leg import PlantConfig
from procedures.reporting import iso230
from procedures.acquisition import plans
from procedures.metrology.uncertainty import UncertaintyInputs, leg_budget, table_budget
from procedures.synthetic import synth_session


@pytest.fixture(scope="module")
def session():
    pts = synth_session({1: PlantConfig()}, plans.iso230_plan().targets_mm, cycles=5, seed=0)
    return pts, iso230.evaluate(pts)[1]


def test_every_value_has_a_budget_listing_every_source(session):
    pts, r = session
    inp = UncertaintyInputs(misalignment_mm=0.5, abbe_offset_mm=20.0, abbe_angle_u_urad=3.0)
    b = leg_budget(r, pts, inp)
    assert set(b.values) == {k for k, v in r.values.items() if v is not None}
    sources = {c.source for c in b.values["E"].contributions}
    assert {"laser", "air temperature", "air pressure", "humidity", "misalignment", "material temperature",
            "expansion coefficient", "Abbe", "resolution", "repeatability"} <= sources
    for v in b.values.values():
        assert v.U_um == pytest.approx(2 * math.sqrt(sum(c.u_um ** 2 for c in v.contributions)))
        assert all(math.isfinite(c.u_input) and math.isfinite(c.sensitivity) for c in v.contributions)
        assert v.value_um == pytest.approx(r.values[v.name])
    json.dumps(b.to_json(), allow_nan=False)


def test_laser_term_is_its_u_times_the_span_and_absent_from_B(session):
    pts, r = session
    b = leg_budget(r, pts, UncertaintyInputs(laser_accuracy_ppm=1.0))
    laser = next(c for c in b.values["E"].contributions if c.source == "laser")
    assert laser.u_input == pytest.approx(0.5)  # stated accuracy is k = 2
    targets = [t.target_mm for t in r.up]
    # sensitivity 1e-3 um/ppm times the (weighted) span between the extremes: within the stroke
    assert 0 < abs(laser.sensitivity) <= 1e-3 * (max(targets) - min(targets)) + 1e-12
    b_laser = [c for c in b.values["B"].contributions if c.source == "laser"]
    assert all(abs(c.sensitivity) < 1e-9 for c in b_laser)  # one target: the scale cancels
    # a worse laser makes E's U grow and leaves B's as it was
    b2 = leg_budget(r, pts, UncertaintyInputs(laser_accuracy_ppm=5.0))
    assert b2.U("E") > b.U("E") + 0.05
    assert b2.U("B") == pytest.approx(b.U("B"), rel=1e-6)


def test_table_entries_grow_with_distance_from_the_laser_zero():
    rows = table_budget([-90.0, -45.0, 0.0, 45.0, 90.0], s_um=0.3, n=5, stroke_mm=180.0)
    U = [r["U_um"] for r in rows]
    assert U[2] == pytest.approx(2 * math.sqrt((0.3 / math.sqrt(5)) ** 2 + (1e-3 / math.sqrt(12)) ** 2 / 5))
    assert U[0] == pytest.approx(U[4]) and U[0] > U[1] > U[2]


def test_inputs_from_a_recorded_config():
    cfg = {"metrology": {"laser_accuracy_ppm": 1.0, "model": "XL-80"}, "legs": {"expansion_um_m_k": 23.0},
           "leg_overrides": {"3": {"expansion_um_m_k": 11.5, "expansion_u_um_m_k": 0.5, "fixed_point_mm": -150.0}}}
    assert UncertaintyInputs.from_record(cfg, 1).expansion_um_m_k == 23.0
    three = UncertaintyInputs.from_record(cfg, 3)
    assert (three.expansion_u_um_m_k, three.fixed_point_mm, three.laser_accuracy_ppm) == (0.5, -150.0, 1.0)
    assert UncertaintyInputs.from_record({}, 1) == UncertaintyInputs()  # a session from before [metrology]
