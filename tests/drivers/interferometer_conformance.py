"""Conformance checks every `drivers.interfaces.Interferometer` implementation must pass.

Reusable: each check takes a `factory` (no arguments -> a fresh, connected Interferometer; the
check closes it) and the axes that have a working beam. Run them against the serial client on the
simulated instrument (tests/drivers/test_interferometer_conformance.py), against the replay
implementation, and against a live instrument on the bench.

They use explicit assertion messages because this module is not a test file (pytest does not
rewrite its asserts).
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from typing import Callable, Iterator, Sequence

import pytest

from drivers.errors import DriverError
from drivers.interfaces import Environment, Interferometer, Reading

Factory = Callable[[], Interferometer]


@contextmanager
def _opened(factory: Factory) -> Iterator[Interferometer]:
    laser = factory()
    try:
        yield laser
    finally:
        laser.close()


def check_satisfies_protocol(factory: Factory, axes: Sequence[int]) -> None:
    with _opened(factory) as laser:
        assert isinstance(laser, Interferometer), f"{type(laser).__name__} lacks methods of Interferometer"


def check_identity(factory: Factory, axes: Sequence[int]) -> None:
    with _opened(factory) as laser:
        first = laser.identity()
        assert isinstance(first, str) and first.strip(), f"identity() must be a non-empty string, got {first!r}"
        assert laser.identity() == first, "identity() changed between two calls"


def check_read(factory: Factory, axes: Sequence[int]) -> None:
    """Each axis gives a Reading for that axis: finite position, beam ok, signal in 0..100,
    instrument time finite and never going backwards."""
    with _opened(factory) as laser:
        last_t = -math.inf
        for axis in axes:
            for _ in range(2):
                r = laser.read(axis)
                assert isinstance(r, Reading), f"read({axis}) returned {type(r).__name__}, not Reading"
                assert r.axis == axis, f"read({axis}) returned a reading of axis {r.axis}"
                assert math.isfinite(r.position_mm), f"read({axis}).position_mm is {r.position_mm}"
                assert r.beam_ok is True, f"read({axis}) returned beam_ok={r.beam_ok} instead of raising BeamBreak"
                assert 0.0 <= r.signal_pct <= 100.0, f"read({axis}).signal_pct = {r.signal_pct} outside 0..100"
                assert math.isfinite(r.t_s), f"read({axis}).t_s is {r.t_s}"
                assert r.t_s >= last_t, f"instrument time went backwards: {r.t_s} after {last_t}"
                last_t = r.t_s


def check_environment(factory: Factory, axes: Sequence[int]) -> None:
    """Plausible air values; a finite material temperature for every axis with a beam."""
    with _opened(factory) as laser:
        env = laser.environment()
        assert isinstance(env, Environment), f"environment() returned {type(env).__name__}"
        assert -10.0 < env.air_temp_c < 50.0, f"air_temp_c = {env.air_temp_c} is not a room temperature"
        assert 500.0 < env.air_pressure_hpa < 1200.0, f"air_pressure_hpa = {env.air_pressure_hpa} implausible"
        assert 0.0 <= env.humidity_pct <= 100.0, f"humidity_pct = {env.humidity_pct} outside 0..100"
        assert isinstance(env.material_temp_c, tuple), "material_temp_c must be a tuple (index 0 = leg 1)"
        for axis in axes:
            temp = env.material_temp_of(axis)
            assert math.isfinite(temp) and -10.0 < temp < 80.0, f"material temperature of leg {axis} is {temp}"


def check_averaging_range(factory: Factory, axes: Sequence[int]) -> None:
    """0..10 s accepted; negative or above 10 s refused with ValueError naming the value."""
    with _opened(factory) as laser:
        laser.set_averaging(0.0)
        laser.set_averaging(0.1)
        for bad in (-0.5, 10.5):
            with pytest.raises(ValueError, match="averaging") as info:
                laser.set_averaging(bad)
            assert str(bad) in str(info.value), f"message does not name the bad value {bad}: {info.value}"
        laser.read(axes[0])  # still usable after refusing


def check_bad_axis(factory: Factory, axes: Sequence[int]) -> None:
    """An axis that does not exist is refused with a clear error, and the device stays usable."""
    with _opened(factory) as laser:
        for bad in (0, 99):
            with pytest.raises((ValueError, DriverError), match="axis") as info:
                laser.read(bad)
            assert str(bad) in str(info.value), f"message does not name axis {bad}: {info.value}"
        laser.read(axes[0])


def check_zero(factory: Factory, axes: Sequence[int], tolerance_mm: float = 0.001) -> None:
    """Right after zero(axis), the axis reads 0 within `tolerance_mm` (the leg has not moved)."""
    with _opened(factory) as laser:
        for axis in axes:
            assert laser.zero(axis) is None, "zero() returns None"
            r = laser.read(axis)
            assert abs(r.position_mm) <= tolerance_mm, f"axis {axis} reads {r.position_mm} mm right after zero()"


def check_close_twice(factory: Factory, axes: Sequence[int]) -> None:
    laser = factory()
    laser.read(axes[0])
    laser.close()
    laser.close()  # must not raise


ALL_CHECKS = (
    check_satisfies_protocol,
    check_identity,
    check_read,
    check_environment,
    check_averaging_range,
    check_bad_axis,
    check_zero,
    check_close_twice,
)
