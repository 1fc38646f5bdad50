"""One set of rules for the points every analysis accepts (fit, diagnosis, verification)."""

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.diagnosis.legdata import split_legs as diagnosis_legs
from procedures.vocabulary import InputError, SchemaError
from procedures.fit.data import split_legs as fit_legs
from procedures.acquisition.points import check_points, usable_rows_by_leg
from procedures.synthetic import synth_session


def points():
    cfgs = {1: PlantConfig().only("noise"), 3: PlantConfig().only("noise")}
    return synth_session(cfgs, np.linspace(-20, 20, 5), cycles=2, seed=0)


def test_failed_points_are_dropped_and_counted_the_same_way_everywhere():
    pts = points()
    pts["error_um"][[2, 3]] = np.nan  # two failed points on leg 1
    rows = usable_rows_by_leg(pts)
    assert sorted(rows) == [1, 3] and rows[1][1] == 2 and rows[3][1] == 0
    assert fit_legs(pts)[1].dropped == diagnosis_legs(pts)[1].dropped == 2
    assert fit_legs(pts)[1].n_points == diagnosis_legs(pts)[1].n_points == 18


@pytest.mark.parametrize("split", [fit_legs, diagnosis_legs])
def test_bad_points_are_refused_with_field_or_row(split):
    pts = points()
    pts["direction"][4] = 2
    with pytest.raises(SchemaError, match="point row 4: field direction is 2, expected"):
        split(pts, "s.h5")
    with pytest.raises(SchemaError, match="lack the field.*error_um"):
        check_points(np.zeros(3, dtype=[("leg", "i2"), ("run", "i4"), ("direction", "i1"), ("target_mm", "f8")]))
    with pytest.raises(InputError, match="no measured points"):
        split(points()[:0], "s.h5")
    everything_failed = points()
    everything_failed["error_um"] = np.nan
    with pytest.raises(InputError, match="s.h5: no point has a finite"):
        split(everything_failed, "s.h5")
