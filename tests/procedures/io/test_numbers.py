"""procedures.io.numbers: one finite-number reader that names the place."""

from __future__ import annotations

import math

import pytest

from procedures.vocabulary import InputError, PlanError
from procedures.io.numbers import NotANumber, finite_float, parse_finite


@pytest.mark.parametrize("value, expected", [("1.5", 1.5), (" -2e3 ", -2000.0), (7, 7.0), (0.25, 0.25)])
def test_finite_values_read(value, expected):
    assert finite_float(value) == expected
    assert parse_finite(value, "here") == expected


@pytest.mark.parametrize("value, parsed", [("x", None), ("", None), (True, None), (None, None), ([1], None),
                                           ("nan", "nan"), ("-inf", "-inf"), ("1e999", "inf"), (math.inf, "inf")])
def test_what_is_not_a_finite_number(value, parsed):
    with pytest.raises(NotANumber) as info:
        finite_float(value)
    assert (info.value.parsed is None) == (parsed is None)
    if parsed is not None:
        assert str(info.value.parsed) == parsed


def test_the_message_names_the_place_and_the_error_type_is_the_callers():
    with pytest.raises(PlanError) as info:
        parse_finite("abc", "plan.csv: line 3: target", PlanError, hint=" (mm expected)")
    assert str(info.value) == "plan.csv: line 3: target: 'abc' is not a number (mm expected)"
    with pytest.raises(InputError, match=r"^t\.csv, row 2, field error_fwd_um: 'inf' is not a finite number$"):
        parse_finite("inf", "t.csv, row 2, field error_fwd_um", hint=" (never shown for inf)")


def test_text_refused_where_only_numbers_are_allowed_and_decimal_comma():
    with pytest.raises(NotANumber):
        finite_float("1.5", text_ok=False)
    assert finite_float("1,5", decimal_comma=True) == 1.5
    with pytest.raises(NotANumber):
        finite_float("1,5")
