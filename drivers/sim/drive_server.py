"""The simulated servo drives: real Modbus servers in front of the leg plants, TCP on 127.0.0.1
(the station's own, drivers/sim/modbus_tcp.py: a thread per connection, held byte for byte to
pymodbus' server by tests/drivers/test_modbus_tcp_server.py) and RTU over a pty (pymodbus').

One server serves every leg on one bus: unit id from the profile (by default leg n = unit n),
each with its own register space laid out by the drive profile (drivers/modbus/profiles/*.toml,
docs/register-map.md, docs/drive-profiles.md). It serves any profile and keeps its line rules
like the real drive would (`FrameStats`): a request longer than the profile's
max_read_words / max_write_words is answered with exception 03 or not at all
(`[protocol] oversize_reply`), a request arriving sooner than min_frame_gap_ms after the
previous reply is counted and not answered (on a real RTU line it would run into the previous
frame), and a set-point latches on the level or the rising edge of the bit as the profile says.
Each unit runs the CiA 402 state machine, trapezoidal moves on the shared clock against its
`LegPlant`, soft-limit refusal with a fault, and the active compensation table. Tables and the
active bank live in "non-volatile memory": a JSON file rewritten atomically on every change and
read at start, like a drive's EEPROM, so a drive killed in the middle of a table push comes
back with its previous table active and intact.

At time scale 0 a move completes within the request that commands it: the server advances the
virtual clock by the move's duration. At scale > 0 the position follows the clock and is
evaluated on every request (and by a background tick, so the plant the interferometer reads
stays current).

Tests and the sample recordings inject faults: `inject_fault` (a latched drive fault),
`set_stalled` (the axis cannot move: set-points accepted, the target never reached) and
`set_unresponsive` (no reply at all).

Run standalone (used by tests that kill it):
    python -m drivers.sim.drive_server [--port 0] [--rtu] [--nv FILE] [--time-scale 0] [--seed 0]
It prints `tcp://127.0.0.1:PORT` (and `rtu PATH`) on stdout once it listens.
"""

from __future__ import annotations

import argparse
import asyncio
import ipaddress
import json
import logging
import math
import os
import random
import signal
import sys
import threading
import time
import tty
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Mapping

from pymodbus.constants import ExcCodes
from pymodbus.exceptions import NoSuchIdException
from pymodbus.framer import FramerType
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.atomic import write_files_atomic
from drivers.errors import DriverError
from drivers.interfaces import Clock
from drivers.modbus.codec import crc16_modbus
from drivers.modbus.profile import DriveProfile
from drivers.sim import device_id
from drivers.sim.modbus_tcp import MbapServer, NoReply
from drivers.sim.motion import SmoothedMove
from drivers.plant.leg import LegPlant
from drivers.sim.position_compare import PositionCompare, TriggerLine
from drivers.states import DriveState

log = logging.getLogger(__name__)

NV_FORMAT = "station-sim-drive-nv"
NV_VERSION = 1
FOLLOWING_LAG_S = 0.002  # following error during motion = velocity * lag (a stiff servo loop)
TICK_S = 0.02  # real seconds between background motion updates at time scale > 0


class NvError(DriverError, ValueError):
    """The drive's non-volatile memory file is unreadable or not ours."""


@dataclass
class _Motion:
    """A trapezoidal move of the nut from p0 to p1 (mm) starting at t0 (s)."""

    p0: float
    p1: float
    t0: float
    v: float  # cruise velocity, mm/s
    a: float  # acceleration, mm/s^2

    def __post_init__(self) -> None:
        d = abs(self.p1 - self.p0)
        self.sign = 1.0 if self.p1 >= self.p0 else -1.0
        if d <= self.v * self.v / self.a:  # triangular: never reaches cruise velocity
            self.t_acc = math.sqrt(d / self.a)
            self.v_peak = self.a * self.t_acc
            self.t_cruise = 0.0
        else:
            self.t_acc = self.v / self.a
            self.v_peak = self.v
            self.t_cruise = (d - self.v * self.v / self.a) / self.v
        self.duration = 2 * self.t_acc + self.t_cruise

    @property
    def t_end(self) -> float:
        return self.t0 + self.duration

    def position(self, t: float) -> float:
        """Nut position (mm) at time t."""
        s = min(max(t - self.t0, 0.0), self.duration)
        ta, tc, a, vp = self.t_acc, self.t_cruise, self.a, self.v_peak
        if s <= ta:
            d = 0.5 * a * s * s
        elif s <= ta + tc:
            d = 0.5 * a * ta * ta + vp * (s - ta)
        else:
            r = self.duration - s
            d = abs(self.p1 - self.p0) - 0.5 * a * r * r
        return self.p0 + self.sign * d

    def velocity(self, t: float) -> float:
        """Signed velocity (mm/s) at time t."""
        s = t - self.t0
        if s <= 0 or s >= self.duration:
            return 0.0
        if s < self.t_acc:
            v = self.a * s
        elif s < self.t_acc + self.t_cruise:
            v = self.v_peak
        else:
            v = self.a * (self.duration - s)
        return self.sign * v


_NOTHING = object()


class DriveModel:
    """One simulated drive (one unit id): its registers and its behaviour.

    Not thread-safe by itself: the server calls it under the shared rig lock.
    """

    def __init__(self, leg: int, plant: LegPlant, clock: Clock, profile: DriveProfile):
        self.leg = leg
        self.plant = plant
        self.clock = clock
        self.p = profile
        self.t = profile.table  # None: a drive without a compensation table
        size = max(r.end for r in profile.registers.values())
        if self.t is not None:
            size = max(size, self.t.bank_end(len(self.t.bank_base) - 1))
        self.regs = [0] * size
        self.readable = bytearray(size)
        self.writable = bytearray(size)
        for r in profile.registers.values():
            self.readable[r.address : r.end] = b"\1" * r.words
            if r.writable:
                self.writable[r.address : r.end] = b"\1" * r.words
        for b in range(self.t.banks if self.t else 0):
            base = self.t.bank_base[b]
            for r in self.t.header.values():
                self.readable[base + r.address : base + r.end] = b"\1" * r.words
                if r.writable:
                    self.writable[base + r.address : base + r.end] = b"\1" * r.words
            for off in (self.t.fwd_offset, self.t.rev_offset):
                a0 = base + off
                self.readable[a0 : a0 + self.t.max_points] = b"\1" * self.t.max_points
                self.writable[a0 : a0 + self.t.max_points] = b"\1" * self.t.max_points
        # drive state
        self.state = DriveState.SWITCH_ON_DISABLED
        self.fault_code = 0
        self.internal_limit = False
        self.set_point_ack = False
        self.cw_prev = 0
        self.motion: _Motion | None = None
        self.nut_mm = plant.x_mm
        self.cmd_mm = plant.x_mm  # last commanded target, leg coordinates
        self.direction = plant.direction
        self.corr_um = 0.0  # table correction applied to the current/last move
        self.unresponsive = False
        self.stalled = False  # the nut cannot move (a jammed screw): set-points accepted, never reached
        self.reads = 0
        self.writes = 0
        self.set_points = 0  # set-points latched (moves started, or refused beyond the soft limits)
        self._bank_cache: dict[int, tuple | None] = {}
        self._statuswords: dict[tuple, int] = {}
        self._internal: dict[str, object] = {}  # values the profile maps to no register
        self._slots: dict[str, tuple] = {}  # name -> (Register | None, address, end, read-only)
        self._held: dict[str, object] = {}  # read-only register -> the value its words encode
        self._spans: dict[tuple[int, int], tuple[frozenset[str], frozenset[int]]] = {}
        # on-the-fly capture (docs/onthefly.md): position-compare output, wired by the rig
        self.compare = PositionCompare()
        self.trigger: TriggerLine | None = None
        self._compare_t = 0.0  # compare pulses are given up to this time of the current move
        # time scale 0: a move waits for the clock (instead of taking its time within the request
        # that started it) while the host only reads position actual: the host traces a pass
        # (ModbusAxis.move_traced); any other read waits for its end, as a status poll would (a
        # write does not: a stop stops it where the clock finds it)
        self.traceable_moves = False
        self._pending = False  # a move started at scale 0 whose time has not been taken yet
        self._init_registers()

    # -- registers ------------------------------------------------------------------------------
    # Every request updates the status registers (twice for a move), so names resolve to their
    # slice once, and a read-only register set to the value it holds is not encoded again (only
    # _set writes those: a client cannot, and the table code writes only bank registers).
    def _slot(self, name: str):
        slot = self._slots.get(name)
        if slot is None:
            r = self.p.registers.get(name)
            slot = self._slots[name] = (r, r.address, r.end, not r.writable) if r is not None else (None, 0, 0, False)
        return slot

    def _set(self, name: str, value) -> None:
        r, a, e, read_only = self._slot(name)
        if r is None:  # the profile maps no register for it: the drive keeps it internally
            self._internal[name] = value
            return
        if read_only:
            if self._held.get(name, _NOTHING) == value:
                return
            self._held[name] = value
        self.regs[a:e] = r.encode(value)

    def _get(self, name: str):
        r, a, e, _ = self._slot(name)
        if r is None:
            return self._internal.get(name, 0)
        return r.decode(self.regs[a:e])

    def _span(self, address: int, count: int) -> tuple[frozenset[str], frozenset[int]]:
        """The registers (names) and table banks a request at `address` (+`count`) covers,
        worked out once per span (a client uses a handful)."""
        key = (address, count)
        span = self._spans.get(key)
        if span is None:
            if len(self._spans) > 4096:  # a fuzzer's spans: do not grow without end
                self._spans.clear()
            end = address + count
            names = frozenset(n for n, r in self.p.registers.items() if r.address < end and r.end > address)
            banks = frozenset(b for b in range(self.t.banks if self.t else 0)
                              if address < self.t.bank_end(b) and end > self.t.bank_base[b])
            span = self._spans[key] = (names, banks)
        return span

    def _init_registers(self) -> None:
        ident = self.p.identity
        lim = self.p.limits
        self._set("vendor", ident["vendor"])
        self._set("product", ident["product"])
        self._set("serial", f"{ident['serial_prefix']}-{self.leg:04d}")
        self._set("firmware", ident["firmware"])
        self._set("map_version", self.p.map_version)
        self._set("soft_limit_min", lim.soft_min_mm)
        self._set("soft_limit_max", lim.soft_max_mm)
        self._set("max_velocity", lim.max_velocity_mm_s)
        self._set("max_acceleration", lim.max_accel_mm_s2)
        self._set("profile_velocity", lim.profile_velocity_mm_s)
        self._set("profile_acceleration", lim.profile_accel_mm_s2)
        self._set("table_enable", 1)
        self._set("active_bank", 0)
        if self.p.protocol.mode_of_operation is not None:
            self._set("modes_of_operation", 0)  # like a drive at power-on: no mode until told
        for b in range(self.t.banks if self.t else 0):
            self._write_header(b, {"point_count": 0, "start_position": 0.0, "spacing": 0.0,
                                   "units": self.t.units_code, "checksum": crc16_modbus([])})
            self._revalidate(b)
        self._update_status()

    def _write_header(self, bank: int, values: Mapping) -> None:
        base = self.t.bank_base[bank]
        words = self.t.encode_header(values)
        for n, r in self.t.header.items():
            if n in values:
                self.regs[base + r.address : base + r.end] = words[r.address : r.end]

    def bank_registers(self, bank: int) -> list[int]:
        """All registers of a bank (header and both entry areas), for non-volatile storage."""
        return self.regs[self.t.bank_base[bank] : self.t.bank_end(bank)]

    def load_bank_registers(self, bank: int, words: list[int]) -> None:
        self.regs[self.t.bank_base[bank] : self.t.bank_end(bank)] = words
        self._revalidate(bank)

    # -- compensation table -----------------------------------------------------------------------
    def _revalidate(self, bank: int) -> bool:
        """Check the bank (count, units, spacing, checksum), set its `valid` register, cache its
        entries in um. Returns validity."""
        base = self.t.bank_base[bank]
        h = self.t.decode_header(self.regs[base : base + self.t.header_words])
        n = h["point_count"]
        ok = 0 <= n <= self.t.max_points and h["units"] == self.t.units_code and (n <= 1 or h["spacing"] > 0)
        if ok:
            fwd = self.regs[self.t.fwd_address(bank) : self.t.fwd_address(bank) + n]
            rev = self.regs[self.t.rev_address(bank) : self.t.rev_address(bank) + n]
            ok = crc16_modbus(fwd + rev) == h["checksum"]
        if ok:
            sc = self.t.entry_scale_um
            to_um = lambda ws: [(w - 0x10000 if w & 0x8000 else w) * sc for w in ws]  # noqa: E731
            self._bank_cache[bank] = (h["start_position"], h["spacing"], to_um(fwd), to_um(rev))
        else:
            self._bank_cache[bank] = None
        vr = self.t.header_register(bank, "valid")
        self.regs[vr.address : vr.end] = vr.encode(1 if ok else 0)
        return ok

    def correction_um(self, target_mm: float, direction: int) -> float:
        """Active table's predicted error at `target_mm` approaching in `direction`, um (linear
        interpolation, end values held outside the table); 0 when disabled or empty."""
        if self.t is None or not self._get("table_enable"):
            return 0.0
        cache = self._bank_cache.get(self._get("active_bank"))
        if not cache or not cache[2]:
            return 0.0
        start, spacing, fwd, rev = cache
        vals = fwd if direction > 0 else rev
        n = len(vals)
        if n == 1:
            return vals[0]
        u = min(max((target_mm - start) / spacing, 0.0), n - 1.0)
        i = min(int(u), n - 2)
        f = u - i
        return vals[i] * (1 - f) + vals[i + 1] * f

    # -- motion -------------------------------------------------------------------------------------
    def refresh(self) -> None:
        """Bring the motion up to the clock's now and the status registers up to date."""
        self._advance()
        self._update_status()

    def _advance(self) -> None:
        """Bring the motion (and the plant) up to the clock's now; the status registers stay."""
        if self.motion is not None and not self.stalled:
            now = self.clock.now()
            m = self.motion
            self._fire_compare(min(now, m.t_end))
            if now >= m.t_end:
                self._arrive()
            else:
                # within the move's ends and never back: the closed form rounds a hair beyond its
                # target near the end, and a hair back between two instants of the deceleration
                # (1e-11 mm, the difference of two large integrals), and the plant takes any step
                # back for a reversal (a new pass offset, the lost motion wound up again: an
                # on-the-fly pass and its anchor on two passes, 0.05 um apart)
                lo, hi = min(m.p0, m.p1), max(m.p0, m.p1)
                pos = min(max(m.position(now), lo), hi)
                self.nut_mm = pos if (pos - self.nut_mm) * m.sign >= 0 else self.nut_mm
                self.plant.move(self.nut_mm, now)
                self._plant_velocity(m.velocity(now))

    def _arrive(self) -> None:
        m = self.motion
        assert m is not None
        self.nut_mm = m.p1
        self.plant.move(m.p1, m.t_end)
        self._plant_stopped(m.t_end, m.sign, m.a)
        self.motion = None

    def _halt(self) -> None:
        """Stop where the nut is now (quick stop, disable, fault)."""
        if self.motion is not None and self.stalled:
            self.motion = None  # a stalled nut is where it stopped
        if self.motion is not None:
            now = self.clock.now()
            if now >= self.motion.t_end:
                self._arrive()
            else:
                self.nut_mm = self.motion.position(now)
                self.plant.move(self.nut_mm, now)
                self._plant_stopped(now, self.motion.sign, self.motion.a)
                self.motion = None
        # the demand becomes where the leg is, so a later move starts from here
        self.cmd_mm = self.nut_mm + self.corr_um / 1000.0

    def _start_move(self, target_mm: float) -> None:
        self.set_points += 1
        lim = self.p.limits
        if not lim.soft_min_mm <= target_mm <= lim.soft_max_mm:
            self.internal_limit = True
            self._fault(self.p.fault_by_name("soft_limit").code)
            log.info("leg %d: refused target %.6f mm beyond soft limits", self.leg, target_mm)
            return
        self.internal_limit = False
        if target_mm != self.cmd_mm:
            self.direction = 1 if target_mm > self.cmd_mm else -1
        self.corr_um = self.correction_um(target_mm, self.direction)
        nut_target = target_mm - self.corr_um / 1000.0  # the drive subtracts the predicted error
        v = min(self._get("profile_velocity"), lim.max_velocity_mm_s)
        a = min(self._get("profile_acceleration"), lim.max_accel_mm_s2)
        self.cmd_mm = target_mm
        self.motion = SmoothedMove(self.nut_mm, nut_target, self.clock.now(), v, a, self._jerk_mm_s3())
        self._compare_t = self.motion.t0
        if getattr(self.clock, "time_scale", 1.0) == 0 and not self.stalled:
            if self.traceable_moves:
                self._pending = True  # its time is taken by the clock, or by the next request
                return
            self._take_move_time()

    def _take_move_time(self) -> None:
        """Time scale 0: the move happens now, on virtual time (the clock jumps to its end; a
        streaming laser samples it on the way, drivers.clock.VirtualClock.add_events)."""
        self._pending = False
        m = self.motion
        if m is None or self.stalled:
            return
        self.clock.sleep(m.t_end - self.clock.now())
        self._advance()

    def _position_only(self, address: int, count: int) -> bool:
        r = self.p.registers.get("position_actual")
        return r is not None and address == r.address and count == r.words

    # -- motion dynamics and position compare (on-the-fly capture, docs/onthefly.md) ---------------
    def _jerk_mm_s3(self) -> float | None:
        """The leg's jerk limit (the plant's motion dynamics; a replay plant has none)."""
        return getattr(getattr(self.plant, "cfg", None), "jerk_mm_s3", None)

    def _plant_velocity(self, v_mm_s: float) -> None:
        setter = getattr(self.plant, "set_velocity", None)
        if setter is not None:
            setter(v_mm_s)

    def _plant_stopped(self, t_s: float, sign: float, decel_mm_s2: float) -> None:
        stopped = getattr(self.plant, "stopped", None)
        if stopped is not None:
            stopped(t_s, int(sign), decel_mm_s2)

    def _fire_compare(self, t_to: float) -> None:
        """Give the compare pulses the current move passes up to `t_to`: the nut (and the plant)
        at each crossing, at its speed, then a pulse on the trigger line."""
        m = self.motion
        if m is None or not self.compare.armed:
            return
        # position actual = nut + the table's shift, and a drive applies its table along the move
        # (the correction at the position it passes, in the move's direction), not only at the
        # target: a pass's samples see the table as a stop-and-go point at the same target does
        sign = int(m.sign)

        def offset_mm(pos_mm: float) -> float:
            return self.correction_um(pos_mm, sign) / 1000.0

        for _, pos_mm, t_s, v_mm_s in self.compare.due(m, self._compare_t, t_to, offset_mm):
            self.nut_mm = pos_mm - offset_mm(pos_mm)
            self.plant.move(self.nut_mm, t_s)
            self._plant_velocity(v_mm_s)
            if self.trigger is not None:
                self.trigger.pulse(self.leg, t_s)
        self._compare_t = max(self._compare_t, t_to)

    def _fault(self, code: int) -> None:
        self._halt()
        self.state = DriveState.FAULT
        self.fault_code = code

    def inject_fault(self, code: int) -> None:
        self._fault(code)
        self._update_status()

    def set_stalled(self, on: bool) -> None:
        """Stall the nut where it is now (on), or free it (off): a move under way then goes on
        from where it stalled, at the same velocity and acceleration, as a new trapezoid."""
        self.refresh()
        on = bool(on)
        if self.stalled and not on and self.motion is not None:
            m = self.motion
            self.motion = SmoothedMove(self.nut_mm, m.p1, self.clock.now(), m.v, m.a, self._jerk_mm_s3())
            self._compare_t = self.motion.t0
        self.stalled = on
        self._update_status()

    # -- CiA 402 state machine ----------------------------------------------------------------------
    def _controlword(self, cw: int) -> None:
        bit = lambda n: self.p.cw_bit(cw, n)  # noqa: E731
        rising_reset = bit("fault_reset") and not self.p.cw_bit(self.cw_prev, "fault_reset")
        prev = self.cw_prev
        self.cw_prev = cw
        if self.state == DriveState.FAULT:
            if rising_reset:
                self.state = DriveState.SWITCH_ON_DISABLED
                self.fault_code = 0
                self.internal_limit = False
            return
        ev, qs, so, eo = bit("enable_voltage"), bit("quick_stop"), bit("switch_on"), bit("enable_operation")
        s = self.state
        if not ev:  # disable voltage
            if s != DriveState.SWITCH_ON_DISABLED:
                self._halt()
            s = DriveState.SWITCH_ON_DISABLED
        elif not qs:  # quick stop
            if s == DriveState.OPERATION_ENABLED:
                self._halt()
                s = DriveState.QUICK_STOP_ACTIVE
            elif s in (DriveState.READY_TO_SWITCH_ON, DriveState.SWITCHED_ON):
                s = DriveState.SWITCH_ON_DISABLED
        elif not so:  # shutdown
            if s in (DriveState.SWITCH_ON_DISABLED, DriveState.SWITCHED_ON, DriveState.OPERATION_ENABLED):
                self._halt()
                s = DriveState.READY_TO_SWITCH_ON
        elif not eo:  # switch on (or disable operation)
            if s in (DriveState.READY_TO_SWITCH_ON, DriveState.OPERATION_ENABLED):
                self._halt()
                s = DriveState.SWITCHED_ON
        else:  # enable operation
            if s in (DriveState.SWITCHED_ON, DriveState.QUICK_STOP_ACTIVE):
                s = DriveState.OPERATION_ENABLED
        self.state = s
        latch = bit("new_set_point")
        if self.p.protocol.set_point_latch == "edge":
            latch = latch and not self.p.cw_bit(prev, "new_set_point")  # CiA 402: the rising edge
        mode = self.p.protocol.mode_of_operation
        if mode is not None and self._get("modes_of_operation") != mode:
            latch = False  # not in profile position mode: a set-point means nothing
        self.set_point_ack = latch and s == DriveState.OPERATION_ENABLED
        if self.set_point_ack:
            self._start_move(self._get("target_position"))

    def _pr_command(self, touched) -> None:
        """A pr_trigger drive (Delta ASDA): alarm reset, servo on/off, run or stop the path."""
        cmd = self.p.commands
        if touched("fault_code") and self._get("fault_code") == cmd["alarm_reset"] and self.state == DriveState.FAULT:
            self.state = DriveState.SWITCH_ON_DISABLED  # the alarm clears with the servo off
            self.fault_code = 0
            self.internal_limit = False
        if touched("servo_on") and self.state != DriveState.FAULT:
            if self._get("servo_on") == cmd["servo_on"]:
                self.state = DriveState.OPERATION_ENABLED
            elif self.state != DriveState.SWITCH_ON_DISABLED:
                self._halt()
                self.state = DriveState.SWITCH_ON_DISABLED
        self.set_point_ack = False
        if touched("pr_trigger") and self.state == DriveState.OPERATION_ENABLED:
            if self._get("pr_trigger") == cmd["stop_path"]:
                self._halt()
            else:
                self.set_point_ack = True
                self._start_move(self._get("target_position"))

    def _update_status(self) -> None:
        moving = self.motion is not None
        key = (self.state, moving, self.internal_limit, self.set_point_ack)
        sw = self._statuswords.get(key)
        if sw is None:  # after every request: each combination composed once
            sw = self._statuswords[key] = self.p.statusword_of(
                self.state,
                target_reached=not moving,
                internal_limit_active=self.internal_limit,
                set_point_acknowledge=self.set_point_ack,
                remote=True,
            )
        if self.motion is not None and not self.stalled:
            now = self.clock.now()
            v = self.motion.velocity(now)
        else:
            v = 0.0
        self._set("statusword", sw)
        self._set("position_actual", self.nut_mm + self.corr_um / 1000.0)
        lag = getattr(getattr(self.plant, "cfg", None), "following_lag_s", None)
        self._set("following_error", v * (lag(v) if lag is not None else FOLLOWING_LAG_S) * 1000.0)
        if "compare_fired" in self.p.registers:
            self._set("compare_fired", self.compare.fired)
        self._set("fault_code", self.fault_code)
        self._set("axial_load", self.plant.load_n)

    # -- requests -----------------------------------------------------------------------------------
    def read(self, address: int, count: int) -> list[int] | ExcCodes:
        self.reads += 1
        if address < 0 or address + count > len(self.regs) or not all(self.readable[address : address + count]):
            return ExcCodes.ILLEGAL_ADDRESS
        if self._pending and not self._position_only(address, count):
            self._take_move_time()
        self.refresh()
        return self.regs[address : address + count]

    def write(self, address: int, values: list[int]) -> ExcCodes | None:
        """Apply a register write; returns a Modbus exception code to refuse it (nothing applied)."""
        self.writes += 1
        count = len(values)
        if address < 0 or address + count > len(self.regs) or not all(self.writable[address : address + count]):
            return ExcCodes.ILLEGAL_ADDRESS
        # a write does not wait for a pending move (a stop stops it where the clock finds it)
        self._advance()
        try:
            return self._apply(address, values)
        finally:
            self._update_status()  # once, whether the write was applied or refused

    def _apply(self, address: int, values: list[int]) -> ExcCodes | None:
        count = len(values)
        names, banks = self._span(address, count)
        touched = names.__contains__
        active = self._get("active_bank")
        if active in banks:
            return ExcCodes.ILLEGAL_ADDRESS  # the active table is read-only while active

        def value(name: str):
            """The register's value as it would be after this write."""
            r = self.p.registers[name]
            words = [values[a - address] if address <= a < address + count else self.regs[a] for a in range(r.address, r.end)]
            return r.decode(words)

        if touched("active_bank"):
            b = value("active_bank")
            if b != active:
                if not 0 <= b < self.t.banks or self._bank_cache.get(b) is None:
                    return ExcCodes.ILLEGAL_VALUE  # unknown bank, or its checksum does not match
                if self.motion is not None:
                    return ExcCodes.DEVICE_BUSY  # never switch tables under a moving axis
        if touched("table_enable") and value("table_enable") not in (0, 1):
            return ExcCodes.ILLEGAL_VALUE
        for n in ("profile_velocity", "profile_acceleration"):
            if touched(n) and not value(n) > 0:
                return ExcCodes.ILLEGAL_VALUE
        if self.p.control == "pr_trigger" and touched("pr_trigger") and \
                value("pr_trigger") not in (self.p.commands["run_path"], self.p.commands["stop_path"]):
            return ExcCodes.ILLEGAL_VALUE  # the simulated drive holds one path and no homing
        self.regs[address : address + count] = values
        for b in banks:
            self._revalidate(b)
        if "compare_count" in self.p.registers and touched("compare_count"):
            self.compare.arm(self._get("compare_start"), self._get("compare_step"), self._get("compare_count"))
        if touched("controlword"):
            self._controlword(self._get("controlword"))
        if self.p.control == "pr_trigger":
            self._pr_command(touched)
        return None

    def touches_nv(self, address: int, count: int) -> bool:
        if self.t is None:
            return False
        names, banks = self._span(address, count)
        return "active_bank" in names or "table_enable" in names or bool(banks)

    def nv_state(self) -> dict:
        return {
            "active_bank": self._get("active_bank"),
            "table_enable": self._get("table_enable"),
            "banks": [self.bank_registers(b) for b in range(self.t.banks if self.t else 0)],
        }

    def load_nv_state(self, state: dict, where: str) -> None:
        banks = state.get("banks")
        nbanks = self.t.banks if self.t else 0
        if not isinstance(banks, list) or len(banks) != nbanks:
            raise NvError(f"{where}: 'banks' must be a list of {nbanks} register lists")
        for b, words in enumerate(banks):
            size = self.t.bank_end(b) - self.t.bank_base[b]
            if not isinstance(words, list) or len(words) != size or not all(isinstance(w, int) and 0 <= w <= 0xFFFF for w in words):
                raise NvError(f"{where}: bank {b} must hold {size} register values 0..65535")
            self.load_bank_registers(b, words)
        active, enable = state.get("active_bank"), state.get("table_enable")
        if (nbanks and active not in range(nbanks)) or enable not in (0, 1):
            raise NvError(f"{where}: active_bank must be 0..{nbanks - 1} and table_enable 0 or 1")
        self._set("active_bank", active)
        self._set("table_enable", enable)
        self._update_status()


@dataclass
class FrameStats:
    """What the simulated drive saw on its line, for tests that check the client keeps the
    profile's rules: the longest read and write requests (words), requests longer than the
    profile allows, requests that came sooner than the profile's silence after the previous
    reply, and the shortest silence seen (seconds, real time)."""

    requests: int = 0
    longest_read_words: int = 0
    longest_write_words: int = 0
    oversize: int = 0
    gap_violations: int = 0
    shortest_gap_s: float = math.inf
    read_write_requests: int = 0  # function 23 requests served
    refused_functions: int = 0  # requests of a function the profile says the drive does not serve (exception 01)


class _LoopRequestHandler(ServerRequestHandler):
    """pymodbus' request handler with the request run as a task of the server's loop. Its own
    `handle_later`, called on that loop already, goes through run_coroutine_threadsafe: a
    concurrent Future, a write to the loop's self-pipe and two more turns of the loop for every
    request (a fifth of the simulated drive's time per point in a replay)."""

    def handle_later(self) -> None:
        task = self.loop.create_task(self.handle_request())
        _REQUESTS.add(task)  # the loop holds tasks weakly: kept until done
        task.add_done_callback(_REQUESTS.discard)


_REQUESTS: set[asyncio.Task] = set()


class _LoopRequests:
    """A pymodbus server whose connections get `_LoopRequestHandler`."""

    def callback_new_connection(self):
        return _LoopRequestHandler(self, self.trace_packet, self.trace_pdu, self.trace_connect)


class _TcpServer(_LoopRequests, ModbusTcpServer):
    pass


class _SerialServer(_LoopRequests, ModbusSerialServer):
    pass


class _Units:
    """The drives as drivers/sim/modbus_tcp.py asks for them: unit id -> leg."""

    def __init__(self, server: "SimDriveServer"):
        self.server = server
        proto = server.profile.protocol
        self.legs = {proto.unit_id(leg): leg for leg in server._models}
        answers = proto.device_identification
        self.objects = device_id.device_objects(server.profile.identity) if answers else None

    def serves(self, unit: int) -> bool:
        return unit in self.legs

    def read_registers(self, unit: int, function: int, address: int, count: int) -> list[int] | int:
        return self.server.request(self.legs[unit], function, address, count, None)

    def write_registers(self, unit: int, function: int, address: int, values: list[int]) -> int | None:
        return self.server.request(self.legs[unit], function, address, len(values), values)

    def device_objects(self, unit: int) -> dict[int, bytes] | None:
        return self.objects


class SimDriveServer:
    """Simulated drives for `plants` (leg -> plant; unit id = leg) behind a pymodbus server.

    `clock` is the rig clock (a VirtualClock: its time scale decides whether moves take time),
    `profile` the register map, `nv_path` the file of the drives' table memory (None = tables
    are lost at stop), `lock` the lock shared with everything else that reads the plants.
    The server runs its asyncio loop in a background thread; start it with `start_tcp()` and/or
    `start_rtu()`, end it with `stop()`.
    """

    def __init__(
        self,
        plants: dict[int, LegPlant],
        clock: Clock,
        profile: DriveProfile,
        nv_path: Path | None = None,
        lock: threading.RLock | None = None,
    ):
        for leg in plants:
            if not 1 <= leg <= 247:
                raise ValueError(f"leg {leg} cannot be a Modbus unit id (1..247)")
        self.clock = clock
        self.profile = profile
        self.lock = lock or threading.RLock()
        self.nv_path = Path(nv_path) if nv_path else None
        self._models = {leg: DriveModel(leg, plant, clock, profile) for leg, plant in sorted(plants.items())}
        if self.nv_path and self.nv_path.exists():
            self._load_nv()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._servers: list = []  # pymodbus servers, on the loop
        self._tcp: list[MbapServer] = []  # the station's Modbus TCP servers, threads of their own
        self._fds: list[int] = []
        self._tick: asyncio.Task | None = None
        self.tcp_port: int | None = None
        self.rtu_port: str | None = None
        self.frames = FrameStats()
        self._last_reply_t = -math.inf  # time.monotonic() when the previous request was answered
        # the transport's delay (bench/bench_latency.py), on the rig's clock: a request reaches
        # the drive `request_delay_s` after it was sent, its reply the host `response_delay_s`
        # after the drive read its registers, each leg plus half a uniform 0..`delay_jitter_s`
        self.request_delay_s = self.response_delay_s = self.delay_jitter_s = 0.0
        self._delay_rng = random.Random(4245)

    # -- non-volatile memory ----------------------------------------------------------------------
    def _load_nv(self) -> None:
        assert self.nv_path is not None
        where = str(self.nv_path)
        try:
            data = json.loads(self.nv_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise NvError(f"{where}: cannot read the drive table memory ({exc}); delete it to start with empty tables") from None
        if not isinstance(data, dict) or data.get("format") != NV_FORMAT or data.get("version") != NV_VERSION:
            raise NvError(f"{where}: not a {NV_FORMAT} file of version {NV_VERSION}")
        legs = data.get("legs", {})
        for leg, model in self._models.items():
            state = legs.get(str(leg))
            if state is not None:
                model.load_nv_state(state, f"{where}: leg {leg}")

    def _save_nv(self) -> None:
        """Write the table memory atomically: temp file, fsync, rename (a kill leaves the old
        or the new file, never half of one)."""
        if self.nv_path is None:
            return
        data = {"format": NV_FORMAT, "version": NV_VERSION,
                "legs": {str(leg): m.nv_state() for leg, m in self._models.items()}}
        text = json.dumps(data, separators=(",", ":"))
        write_files_atomic({self.nv_path: text})

    # -- request handling (runs in the server thread) ------------------------------------------------
    def _line_rules(self, count: int, write: bool) -> ExcCodes | None:
        """Apply the profile's line rules to a request of `count` words; count what breaks them.
        Returns the exception to answer with; raises NoReply for no answer."""
        proto = self.profile.protocol
        f = self.frames
        now = time.monotonic()
        gap = now - self._last_reply_t
        f.requests += 1
        f.shortest_gap_s = min(f.shortest_gap_s, gap)
        if write:
            f.longest_write_words = max(f.longest_write_words, count)
        else:
            f.longest_read_words = max(f.longest_read_words, count)
        if gap * 1000.0 < proto.min_frame_gap_ms:
            f.gap_violations += 1
            # on an RTU line the frame would have merged with the previous one: no reply
            raise NoReply(f"request {gap * 1000.0:.2f} ms after the previous reply, the drive needs "
                                    f"{proto.min_frame_gap_ms:g} ms")
        if count > (proto.max_write_words if write else proto.max_read_words):
            f.oversize += 1
            if proto.oversize_reply == "silence":
                raise NoReply(f"request of {count} words, longer than the drive accepts")
            return ExcCodes.ILLEGAL_VALUE  # exception 03, as the manuals say
        return None

    async def _action(self, leg, function_code, start_address, address, count, registers, set_values):
        """pymodbus' datastore action (the RTU server): `_request` into its register buffer."""
        try:
            res = self.request(leg, function_code, address, count, set_values)
        except NoReply as exc:
            raise NoSuchIdException(str(exc)) from None
        if isinstance(res, list):
            registers[address - start_address : address - start_address + count] = res
            return None
        return res

    def request(self, leg: int, function_code: int, address: int, count: int,
                set_values: list[int] | None) -> list[int] | ExcCodes | None:
        """One request to drive `leg`, as both servers pass it: a read (`set_values` None) returns
        the registers or an exception; a write returns None or an exception. Function 23 comes
        as its write, then its read. Raises NoReply for a request the drive would not answer."""
        delayed = self.request_delay_s > 0 or self.response_delay_s > 0 or self.delay_jitter_s > 0
        if delayed:  # on the way in (outside the lock: a streaming laser samples the clock's stops)
            half_jitter_s = 0.5 * self._delay_rng.uniform(0.0, self.delay_jitter_s)
            if function_code != 23 or set_values is not None:
                self.clock.sleep(self.request_delay_s + half_jitter_s)
        try:
            return self._request(leg, function_code, address, count, set_values)
        finally:
            if delayed and (function_code != 23 or set_values is None):
                self.clock.sleep(self.response_delay_s + half_jitter_s)  # on the way back

    def _request(self, leg: int, function_code: int, address: int, count: int,
                 set_values: list[int] | None) -> list[int] | ExcCodes | None:
        try:
            with self.lock:
                if function_code == 23:
                    refused = self._read_write_rules(count, set_values is not None)
                else:
                    refused = self._line_rules(count, set_values is not None)
                if refused is not None:
                    return refused
                model = self._models[leg]
                if model.unresponsive:
                    raise NoReply(f"leg {leg} set unresponsive")  # no reply at all
                if set_values is None:
                    return model.read(address, count)
                values = [int(v) for v in set_values]
                res = model.write(address, values)
                if res is None and model.touches_nv(address, count):
                    self._save_nv()
                return res
        finally:
            self._last_reply_t = time.monotonic()

    def _read_write_rules(self, count: int, write: bool) -> ExcCodes | None:
        """Function 23: exception 01 (illegal function) from a drive whose profile says it does
        not serve it; else the line rules once for the request (its write part), and the read
        part's length against max_read_words."""
        if not self.profile.protocol.read_write_multiple:
            self.frames.refused_functions += write
            return ExcCodes.ILLEGAL_FUNCTION
        if write:
            self.frames.read_write_requests += 1
            return self._line_rules(count, write=True)
        f = self.frames
        f.longest_read_words = max(f.longest_read_words, count)
        if count > self.profile.protocol.max_read_words:
            f.oversize += 1
            return ExcCodes.ILLEGAL_VALUE
        return None

    async def _silent(self, *args):
        raise NoSuchIdException("no drive at this unit id")  # an absent drive does not answer

    def _devices(self) -> list[SimDevice]:
        size = len(next(iter(self._models.values())).regs)
        devices = [
            SimDevice(id=self.profile.protocol.unit_id(leg), simdata=[SimData(address=0, count=size, datatype=DataType.REGISTERS)],
                      action=partial(self._action, leg))
            for leg in self._models
        ]  # fmt: skip
        # unit ids without a drive: same address space, so every request reaches _silent
        devices.append(SimDevice(id=0, simdata=[SimData(address=0, count=size, datatype=DataType.REGISTERS)], action=self._silent))
        return devices

    def _device_identification(self, server) -> None:
        """Function 43/14 per drive: answered from the profile's [identity] when the profile says
        the drive answers it, else exception 01 (drivers/sim/device_id.py)."""
        answers = self.profile.protocol.device_identification
        objects = device_id.device_objects(self.profile.identity) if answers else None
        device_id.install(server, {self.profile.protocol.unit_id(leg): objects for leg in self._models})

    # -- life cycle ---------------------------------------------------------------------------------
    def _ensure_loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None:
            self._loop = asyncio.new_event_loop()
            self._thread = threading.Thread(target=self._loop.run_forever, name="sim-drive-server", daemon=True)
            self._thread.start()
            if getattr(self.clock, "time_scale", 0.0) > 0:
                self._call(self._start_tick())
        return self._loop

    def _call(self, coro, timeout_s: float = 10.0):
        assert self._loop is not None
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result(timeout_s)

    async def _start_tick(self) -> None:
        async def tick():
            while True:
                await asyncio.sleep(TICK_S)
                self.sync()

        self._tick = asyncio.get_running_loop().create_task(tick())

    def sync_leg(self, leg: int) -> int:
        """Bring drive `leg`'s motion (and its plant) up to the clock's now: 0 at rest, 1 moving,
        2 moving in a move the host traces (taking its time from the clock, DriveModel)."""
        with self.lock:
            m = self._models.get(leg)
            if m is None or m.motion is None:
                return 0
            m.refresh()
            return 0 if m.motion is None else (2 if m._pending else 1)

    def set_traceable_moves(self, on: bool) -> None:
        """Time scale 0: moves wait for the clock while the host traces them (DriveModel)."""
        with self.lock:
            for m in self._models.values():
                m.traceable_moves = bool(on)

    def sync(self) -> None:
        """Bring every drive's motion (and its plant) up to the clock's now."""
        with self.lock:
            for m in self._models.values():
                m.refresh()

    def start_tcp(self, host: str = "127.0.0.1", port: int = 0, engine: str = "station") -> int:
        """Serve Modbus TCP on `host` (loopback only) and `port` (0 = any free); returns the port.
        `engine` "station" is drivers/sim/modbus_tcp.py, "pymodbus" pymodbus' server (kept for
        the test that holds the two to the same bytes)."""
        if not ipaddress.ip_address(host).is_loopback:
            raise ValueError(f"the simulated drive serves loopback only, not {host}; use 127.0.0.1")
        if engine not in ("station", "pymodbus"):
            raise ValueError(f"unknown Modbus TCP server engine {engine!r}: station or pymodbus")
        self._ensure_loop()
        if engine == "station":
            server = MbapServer(_Units(self), host, port, name="sim-drive-tcp")
            try:
                self.tcp_port = server.start()
            except OSError as exc:
                raise OSError(exc.errno, f"cannot listen on {host}:{port} ({exc.strerror or exc})") from None
            self._tcp.append(server)
            return self.tcp_port

        async def start():
            server = _TcpServer(self._devices(), address=(host, port), ignore_missing_devices=True)
            self._device_identification(server)
            try:
                await server.serve_forever(background=True)
            except RuntimeError:
                raise OSError(98, f"cannot listen on {host}:{port} (address in use?)") from None
            self._servers.append(server)
            return server.transport.sockets[0].getsockname()[1]

        self.tcp_port = self._call(start())
        return self.tcp_port

    def start_rtu(self, baudrate: int = 115200) -> str:
        """Serve Modbus RTU on a pseudo-terminal; returns the path a client opens
        (e.g. /dev/pts/7; URL rtu:///dev/pts/7?baud=115200)."""
        self._ensure_loop()

        async def start():
            # The server owns one pty, the client opens another; we copy bytes between the two
            # masters (a pty master has no path a client could open).
            m_srv, s_srv = os.openpty()
            m_cli, s_cli = os.openpty()
            for fd in (s_srv, s_cli):
                tty.setraw(fd)  # no echo or line editing before the client configures it
            self._fds += [m_srv, s_srv, m_cli, s_cli]
            loop = asyncio.get_running_loop()
            for src, dst in ((m_srv, m_cli), (m_cli, m_srv)):
                os.set_blocking(src, False)
                loop.add_reader(src, partial(self._copy, src, dst))
            server = _SerialServer(self._devices(), framer=FramerType.RTU, port=os.ttyname(s_srv),
                                        baudrate=baudrate, ignore_missing_devices=True)
            self._device_identification(server)
            await server.serve_forever(background=True)
            self._servers.append(server)
            return os.ttyname(s_cli)

        self.rtu_port = self._call(start())
        return self.rtu_port

    @staticmethod
    def _copy(src: int, dst: int) -> None:
        try:
            data = os.read(src, 4096)
        except (BlockingIOError, OSError):
            return
        view = memoryview(data)
        while view:
            try:
                n = os.write(dst, view)
            except BlockingIOError:
                continue
            except OSError:
                return
            view = view[n:]

    def stop(self) -> None:
        """Stop serving and end the server thread. Idempotent."""
        if self._loop is None:
            return

        async def shutdown():
            if self._tick:
                self._tick.cancel()
            for server in self._servers:
                await server.shutdown()
            loop = asyncio.get_running_loop()
            for fd in self._fds:
                try:
                    loop.remove_reader(fd)
                except (ValueError, OSError):
                    pass

        for server in self._tcp:
            server.close()
        self._tcp.clear()
        try:
            self._call(shutdown())
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            if self._thread:
                self._thread.join(5.0)
            self._loop.close()
            for fd in self._fds:
                try:
                    os.close(fd)
                except OSError:
                    pass
            self._fds.clear()
            self._servers.clear()
            self._loop = None
            self._thread = None

    def __enter__(self) -> "SimDriveServer":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # -- fault injection and inspection (tests, sweep runner) --------------------------------------
    def inject_fault(self, leg: int, code: int | str) -> None:
        """Put drive `leg` into fault with `code` (an int, or a fault name from the profile)."""
        if isinstance(code, str):
            code = self.profile.fault_by_name(code).code
        with self.lock:
            self._models[leg].inject_fault(int(code))

    def set_points(self, leg: int) -> int:
        """How many set-points drive `leg` has latched since it started: every move it was told
        to make (a jog, a move, a sweep's point), whether it moved or refused the target."""
        with self.lock:
            return self._models[leg].set_points

    def set_stalled(self, leg: int, on: bool = True) -> None:
        """Make drive `leg`'s axis unable to move (a jammed screw, a seized bearing): it stays
        enabled and accepts set-points, but the nut stays where it is and the target is never
        reached, until `set_stalled(leg, False)` frees it. The station sees a move that does
        not arrive: a real non-arrival, which its move timeout must catch."""
        with self.lock:
            self._models[leg].set_stalled(on)

    def set_unresponsive(self, leg: int, on: bool = True) -> None:
        """Make drive `leg` ignore every request (no reply), as a drive with a dead link would."""
        with self.lock:
            self._models[leg].unresponsive = bool(on)

    def connect_trigger(self, line: TriggerLine) -> None:
        """Wire every drive's position-compare output to `line` (on-the-fly capture)."""
        with self.lock:
            for m in self._models.values():
                m.trigger = line

    def frame_stats(self) -> FrameStats:
        """A copy of what the drives saw on their line (see FrameStats)."""
        with self.lock:
            return FrameStats(**vars(self.frames))

    def request_counts(self, leg: int) -> tuple[int, int]:
        """(reads, writes) drive `leg` has answered or refused since start."""
        with self.lock:
            m = self._models[leg]
            return m.reads, m.writes

    def state(self, leg: int) -> DriveState:
        """CiA 402 state of drive `leg` (inspection for tests)."""
        with self.lock:
            return self._models[leg].state


def main(argv: list[str] | None = None) -> int:
    from drivers.clock import VirtualClock
    from drivers.plant.leg import default_leg_configs

    ap = argparse.ArgumentParser(prog="python -m drivers.sim.drive_server", description="Simulated leg servo drives (Modbus).")
    ap.add_argument("--port", type=int, default=0, help="Modbus TCP port on 127.0.0.1 (0 = any free)")
    ap.add_argument("--rtu", action="store_true", help="also serve Modbus RTU on a pty")
    ap.add_argument("--nv", type=Path, help="file for the drives' table memory")
    ap.add_argument("--time-scale", type=float, default=0.0, help="real seconds per simulated second")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--legs", type=int, default=6)
    ap.add_argument("--profile", type=Path, help="drive profile TOML (default: built-in)")
    args = ap.parse_args(argv)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    clock = VirtualClock(args.time_scale)
    plants = {i + 1: LegPlant(cfg, seed=args.seed * 100 + i + 1) for i, cfg in enumerate(default_leg_configs(args.seed, args.legs))}
    try:
        server = SimDriveServer(plants, clock, DriveProfile.load(args.profile), nv_path=args.nv)
        port = server.start_tcp("127.0.0.1", args.port)
    except (ValueError, OSError) as exc:
        print(f"drive_server: error: {exc}", file=sys.stderr)
        return 2
    print(f"tcp://127.0.0.1:{port}", flush=True)
    if args.rtu:
        print(f"rtu {server.start_rtu()}", flush=True)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    try:
        done.wait()
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
