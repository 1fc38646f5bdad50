"""ServoAxis conformance checks, reusable for every implementation (Modbus on TCP, on RTU,
replay, ...).

Each check takes a factory returning a fresh `AxisUnderTest`: a connected axis plus, where the
implementation has one, a view of the physics behind it (the plant's true position, a way to
inject a drive fault). A check asserts behaviour the `ServoAxis` contract promises
(drivers/interfaces.py); the factory's owner cleans up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import pytest

from drivers.errors import DriveFault, SoftLimitError, TableError
from drivers.interfaces import ServoAxis, TableBank


@dataclass
class AxisUnderTest:
    axis: ServoAxis
    true_position_mm: Callable[[], float] | None = None  # the leg's real position (plant), if known
    inject_fault: Callable[[int], None] | None = None  # put the drive into fault with a code
    fault_code: int = 0x2310  # a code inject_fault accepts
    tolerance_um: float = 20.0  # how far the real leg may be from the target (leg errors)
    position_tol_um: float = 1.0  # drive-reported position vs target once arrived
    supports_tables: bool = True  # False: table_spec() must be None and every table method refuse
    reports_fault_code: bool = True  # False: the drive maps no fault-code register (code reads 0)


Factory = Callable[[], AxisUnderTest]


def check_identity_and_limits(make: Factory) -> None:
    aut = make()
    ax = aut.axis
    assert isinstance(ax, ServoAxis)
    ident = ax.identity()
    assert isinstance(ident, str) and ident.strip(), "identity must be a non-empty string"
    assert ax.identity() == ident, "identity must be stable"
    lim = ax.limits()
    assert lim.min_mm < 0.0 < lim.max_mm, f"mid-stroke reference must lie inside the soft limits {lim}"
    assert lim.max_velocity_mm_s > 0 and lim.max_accel_mm_s2 > 0


def check_enable_disable(make: Factory) -> None:
    ax = make().axis
    ax.disable()
    assert not ax.status().enabled
    ax.enable()
    assert ax.status().enabled
    ax.enable()  # idempotent
    assert ax.status().state == "operation_enabled"
    ax.disable()
    st = ax.status()
    assert not st.enabled and not st.fault


def check_moves_track_targets(make: Factory) -> None:
    aut = make()
    ax = aut.axis
    lim = ax.limits()
    ax.enable()
    targets = [0.0, 10.0, -20.5, lim.max_mm - 1.0, lim.min_mm + 1.0, 3.25, 3.25, 3.2501]
    for t in targets:
        st = ax.move_to(t)
        assert st.target_reached and not st.moving and not st.fault and st.enabled
        assert abs(st.position_mm - t) * 1000.0 <= aut.position_tol_um, f"drive reports {st.position_mm} for target {t}"
        again = ax.status()
        assert abs(again.position_mm - st.position_mm) * 1000.0 <= aut.position_tol_um
        if aut.true_position_mm:
            err_um = (aut.true_position_mm() - t) * 1000.0
            assert abs(err_um) <= aut.tolerance_um, f"leg is {err_um:.2f} um off target {t}"


def check_soft_limit_refused_before_motion(make: Factory) -> None:
    aut = make()
    ax = aut.axis
    lim = ax.limits()
    ax.enable()
    ax.move_to(5.0)
    before = ax.status().position_mm
    true_before = aut.true_position_mm() if aut.true_position_mm else None
    for bad in (lim.max_mm + 0.001, lim.min_mm - 1.0, lim.max_mm + 1000.0, math.nan, math.inf):
        with pytest.raises(SoftLimitError) as info:
            ax.move_to(bad)
        text = str(info.value)
        assert "soft limit" in text or "finite" in text, text
        assert "nothing moved" in text, text
    st = ax.status()
    assert st.enabled and not st.fault, "a refused target must not fault or disable the drive"
    assert st.position_mm == before
    if aut.true_position_mm:
        assert aut.true_position_mm() == true_before


def check_move_requires_enable(make: Factory) -> None:
    aut = make()
    ax = aut.axis
    ax.enable()
    ax.move_to(1.0)
    ax.disable()
    true_before = aut.true_position_mm() if aut.true_position_mm else None
    with pytest.raises(DriveFault) as info:
        ax.move_to(2.0)
    assert "enable" in str(info.value)
    assert abs(ax.status().position_mm - 1.0) * 1000.0 <= aut.position_tol_um
    if aut.true_position_mm:
        assert aut.true_position_mm() == true_before


def check_fault_and_reset(make: Factory) -> None:
    aut = make()
    if aut.inject_fault is None:
        pytest.skip("this implementation cannot inject a drive fault")
    ax = aut.axis
    ax.enable()
    ax.move_to(0.0)
    aut.inject_fault(aut.fault_code)
    st = ax.status()
    code = aut.fault_code if aut.reports_fault_code else 0
    assert st.fault and st.state == "fault" and st.fault_code == code
    text = ax.fault_text(st.fault_code)  # the drive describes its own fault (shown by the Rig page)
    assert isinstance(text, str) and f"0x{st.fault_code:04X}" in text
    with pytest.raises(DriveFault) as info:
        ax.move_to(1.0)
    assert info.value.code == code
    ax.stop()  # must not raise after a fault
    with pytest.raises(DriveFault):
        ax.enable()  # refuses while in fault
    ax.reset_fault()
    st = ax.status()
    assert not st.fault and st.fault_code == 0
    ax.enable()
    st = ax.move_to(1.0)
    assert st.target_reached and abs(st.position_mm - 1.0) * 1000.0 <= aut.position_tol_um


def check_stop_is_safe(make: Factory) -> None:
    aut = make()
    ax = aut.axis
    ax.stop()  # before anything
    ax.enable()
    ax.move_to(2.0)
    ax.stop()
    st = ax.status()
    assert not st.enabled and not st.fault, f"after a quick stop the drive must not stay enabled ({st.state})"
    ax.stop()
    ax.disable()
    ax.stop()
    ax.enable()
    assert ax.move_to(-2.0).target_reached


def _sample_table(start_mm: float, spacing_mm: float, n: int, phase: float) -> TableBank:
    fwd = tuple(round(12.0 * math.sin(0.3 * i + phase) + 0.02 * i, 2) for i in range(n))
    rev = tuple(round(e + 1.5, 2) for e in fwd)
    return TableBank(start_mm, spacing_mm, fwd, rev)


def check_tables(make: Factory) -> None:
    aut = make()
    ax = aut.axis
    if not aut.supports_tables:
        # a drive without a table says so, and refuses every table operation
        assert ax.table_spec() is None
        for call in (lambda: ax.active_bank(), lambda: ax.read_table(1), lambda: ax.activate_table(1),
                     lambda: ax.write_table(1, _sample_table(-90.0, 2.5, 5, 0.4))):
            with pytest.raises(TableError, match="holds no compensation table"):
                call()
        assert not ax.status().fault  # refusing a table operation does not fault the drive
        return
    active = ax.active_bank()
    other = 1 - active
    table = _sample_table(-90.0, 2.5, 73, 0.4)
    ax.write_table(other, table)
    back = ax.read_table(other)
    assert back.point_count == table.point_count
    assert back.start_mm == pytest.approx(table.start_mm, abs=1e-6)
    assert back.spacing_mm == pytest.approx(table.spacing_mm, abs=1e-6)
    assert back.error_fwd_um == pytest.approx(table.error_fwd_um, abs=0.006)
    assert back.error_rev_um == pytest.approx(table.error_rev_um, abs=0.006)
    assert ax.active_bank() == active, "writing must not activate"
    with pytest.raises(TableError):
        ax.write_table(active, table)  # never write the table in use
    ax.activate_table(other)
    assert ax.active_bank() == other
    assert ax.status().active_bank == other
    with pytest.raises(TableError):
        ax.write_table(other, _sample_table(-50.0, 1.0, 10, 1.0))
    assert ax.read_table(other) == back, "a refused write must leave the active table intact"
    ax.activate_table(active)
    assert ax.active_bank() == active


def check_close_idempotent(make: Factory) -> None:
    ax = make().axis
    ax.status()
    ax.close()
    ax.close()


CHECKS = [
    check_identity_and_limits,
    check_enable_disable,
    check_moves_track_targets,
    check_soft_limit_refused_before_motion,
    check_move_requires_enable,
    check_fault_and_reset,
    check_stop_is_safe,
    check_tables,
    check_close_idempotent,
]
