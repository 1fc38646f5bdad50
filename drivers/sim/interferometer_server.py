"""A simulated six-axis laser interferometer on a real pseudo-terminal.

It speaks the protocol of docs/interferometer-protocol.md (drivers.interferometer.protocol) on the
master side of a pty; the station's client opens the slave path like any serial port. Each axis
reads one leg's plant (`LegPlant.measured_position_mm`), so what the laser sees is what the
simulated drive did. Faults on demand: beam break (per axis), weak signal, line noise (the next n
replies corrupted) and a silent instrument.

Threading: one reader thread serves the pty; it blocks in select() on the pty and a wake-up pipe
(no polling sleeps, so a reply costs well under a millisecond). Plant access takes the `lock`
shared with the simulated drive.
"""

from __future__ import annotations

import math
import os
import select
import threading
from collections import Counter

import numpy as np

from drivers.interferometer import protocol as p
from drivers.interfaces import Clock
from drivers.plant.leg import LegPlant
from drivers.sim.pty_server import PtyServer

GARBAGE_KINDS = ("checksum", "truncated", "noise", "unterminated")
_DEFAULT_GARBAGE_CYCLE = ("checksum", "truncated", "noise")  # the ones a client detects at once


class SimInterferometer(PtyServer):
    """Simulated interferometer. `plants` maps axis (= leg) number to its plant; axes without
    a plant report BEAM (no beam aligned on them). `air` is (air_temp_c, air_pressure_hpa,
    humidity_pct) around which the air sensors wander slowly. `seed` fixes sensor noise and
    line noise. `signal_pct` is the nominal beam signal strength.

    Use: ``port = sim.start()`` -> slave pty path for the client; ``sim.stop()`` when done
    (also as a context manager).
    """

    name = "sim-interferometer"

    def __init__(
        self,
        plants: dict[int, LegPlant],
        clock: Clock,
        lock: threading.RLock | None = None,
        air: tuple[float, float, float] = (20.0, 1013.25, 45.0),
        seed: int = 0,
        axes: int = 6,
        identity: tuple[str, str, str, str] = ("StationSim", "LI-6", "SIM-0001", "1.0"),
        signal_pct: float = 92.0,
        offset_um: float = 0.0,
    ):
        bad = [a for a in plants if not 1 <= a <= axes]
        if bad:
            raise ValueError(f"simulated interferometer has axes 1..{axes}; plants given for axes {bad}")
        self.plants = dict(plants)
        # added to every reading after the zero: a station's bias (station compare's tests; 0 = off)
        self.offset_mm = 1e-3 * float(offset_um)
        self.clock = clock
        self.lock = lock if lock is not None else threading.RLock()
        self.air = tuple(float(v) for v in air)
        # the air compensation the simulated readings carry: AUTO from the air sensors ENV? reports,
        # by the modified Edlen equation, HeNe vacuum wavelength. The plant's readings are true
        # displacements, i.e. this compensation taken as exact. `set_compensation` changes what
        # COMP? reports (a misconfigured instrument, for re-correction tests).
        self.compensation = p.CompensationReply("AUTO", "EDLEN", 632.991, math.nan, math.nan, math.nan, 450.0, 0.0)
        self._air_offset_c = 0.0  # set_air_sensor_offset: a faulty air temperature sensor
        self._air_index = None
        self.axes = int(axes)
        self.identity = tuple(identity)
        self._rng = np.random.default_rng(seed)
        self._air_phase = self._rng.uniform(0, 2 * math.pi, size=3)
        self._averaging_s = 0.0
        self._beam_break: set[int] = set()
        self._signal_pct = {axis: float(signal_pct) for axis in range(1, self.axes + 1)}
        self._last_position_mm = {axis: 0.0 for axis in range(1, self.axes + 1)}
        # plant position (mm) where each axis was zeroed: readings are displacements from it;
        # the sweep zeroes at mid-stroke (0), so readings are then in leg coordinates
        self._datum_mm = {axis: 0.0 for axis in range(1, self.axes + 1)}
        self._faults = threading.Lock()
        self._garbage_left = 0
        self._garbage_kind: str | None = None
        self._garbage_count = 0
        self._silent = False
        # on-the-fly capture: per axis [armed count, samples (position text, status, signal, t_s)]
        self._capture: dict[int, list] = {axis: [0, []] for axis in range(1, self.axes + 1)}
        self.commands = Counter()  # command word -> count received (statistics for tests/bench)
        self.failures: list[BaseException] = []  # exceptions inside the server (should stay empty)
        self._init_pty()

    # -- faults on demand ---------------------------------------------------------------------

    def set_beam_break(self, axis: int, on: bool) -> None:
        """Interrupt (on=True) or restore the beam of `axis`: POS replies say BEAM, signal 0."""
        with self._faults:
            (self._beam_break.add if on else self._beam_break.discard)(axis)

    def set_signal_pct(self, axis: int, signal_pct: float) -> None:
        """Beam signal strength of `axis`, percent; below p.LOW_SIGNAL_PCT it reports LOW."""
        with self._faults:
            self._signal_pct[axis] = float(signal_pct)

    def inject_garbage(self, n: int, kind: str | None = None) -> None:
        """Corrupt the next `n` replies (line noise). `kind`: "checksum" (one bit flipped),
        "truncated" (the end of the line lost, terminator kept), "noise" (random bytes),
        "unterminated" (line cut, no terminator: the client only notices at its timeout);
        None cycles through the first three."""
        if kind is not None and kind not in GARBAGE_KINDS:
            raise ValueError(f"garbage kind must be one of {GARBAGE_KINDS}, got {kind!r}")
        with self._faults:
            self._garbage_left = int(n)
            self._garbage_kind = kind

    def set_silent(self, on: bool) -> None:
        """A silent instrument: commands are read and ignored, nothing is answered."""
        with self._faults:
            self._silent = bool(on)

    def set_compensation(self, compensation: "p.CompensationReply") -> None:
        """What COMP? reports from now on (the readings themselves do not change)."""
        self.compensation = compensation

    def set_air_sensor_offset(self, temp_offset_c: float, index=None) -> None:
        """A faulty air temperature sensor reading `temp_offset_c` too high: ENV? reports it, and
        the AUTO compensation uses it, so every displacement (POS?) is scaled by n_true / n_used.
        `index(temp_c, pressure_pa, humidity_pct) -> n` computes the index (the composition root
        passes procedures.metrology.air's; drivers do not import procedures); without one the
        linearised -0.93 ppm/K of air near 20 degC at 633 nm is used."""
        with self._faults:
            self._air_offset_c = float(temp_offset_c)
            self._air_index = index

    @property
    def averaging_s(self) -> float:
        return self._averaging_s

    # -- serving ------------------------------------------------------------------------------

    def _serve(self) -> None:
        pending = bytearray()
        while True:
            ready, _, _ = select.select([self._master, self._wake_r], [], [])
            if self._wake_r in ready:
                return
            try:
                data = os.read(self._master, 4096)
            except OSError as exc:  # pragma: no cover - slave fd is held open, so not expected
                self.failures.append(exc)
                return
            pending += data
            while True:
                end = pending.find(p.COMMAND_TERMINATOR)
                if end < 0:
                    if len(pending) > p.MAX_LINE_BYTES:
                        pending.clear()
                        self._reply(p.format_error(p.ERR_LINE_TOO_LONG, f"no terminator within {p.MAX_LINE_BYTES} bytes"))
                    break
                line = bytes(pending[:end]).rstrip(b"\r")
                del pending[: end + 1]
                try:
                    reply = self._handle(line)
                except Exception as exc:  # keep serving; tests check `failures` stays empty
                    self.failures.append(exc)
                    continue
                if reply is not None:
                    self._reply(reply)

    def _reply(self, reply: bytes) -> None:
        with self._faults:
            if self._silent:
                return
            if self._garbage_left > 0:
                self._garbage_left -= 1
                kind = self._garbage_kind or _DEFAULT_GARBAGE_CYCLE[self._garbage_count % len(_DEFAULT_GARBAGE_CYCLE)]
                self._garbage_count += 1
                reply = self._corrupt(reply, kind)
        view = memoryview(reply)
        while view:
            view = view[os.write(self._master, view) :]

    def _corrupt(self, reply: bytes, kind: str) -> bytes:
        body = reply[: -len(p.TERMINATOR)]
        rng = self._rng
        if kind == "checksum":
            # flip the lowest bit of one character before the '*': the checksum no longer fits
            i = int(rng.integers(0, body.rfind(b"*")))
            return body[:i] + bytes([body[i] ^ 0x01]) + body[i + 1 :] + p.TERMINATOR
        if kind == "truncated":
            return body[: max(1, len(body) // 2)] + p.TERMINATOR
        if kind == "noise":
            junk = rng.integers(0, 256, size=int(rng.integers(8, 40)), dtype=np.uint8).tobytes()
            return junk.replace(b"\r", b"\x00").replace(b"\n", b"\x00") + p.TERMINATOR
        return body[: max(1, len(body) // 2)]  # unterminated

    def _handle(self, line: bytes) -> bytes | None:
        word, args = p.parse_command(line)
        if not word:
            return None  # blank line: nothing to answer
        self.commands[word] += 1
        with self._faults:
            if self._silent:
                return None
        if word == p.CMD_IDN:
            return p.frame_reply("IDN", *self.identity) if not args else _bad_args(word)
        if word == p.CMD_POS:
            axis = self._axis(args)
            return axis if isinstance(axis, bytes) else self._position(axis)
        if word == p.CMD_ENV:
            return self._environment() if not args else _bad_args(word)
        if word == p.CMD_COMP:
            return p.format_compensation(self.compensation) if not args else _bad_args(word)
        if word == p.CMD_ZERO:
            axis = self._axis(args)
            if isinstance(axis, bytes):
                return axis
            with self.lock:
                plant = self.plants.get(axis)
                if plant is not None:
                    # the plant forgets the error offset here; the datum makes later readings
                    # displacements from this point, as a real interferometer's zero does
                    plant.zero_here(self.clock.now())
                    self._datum_mm[axis] = plant.x_mm
            return p.frame_reply("OK")
        if word == p.CMD_AVG_QUERY:
            return p.frame_reply("AVG", p.format_averaging(self._averaging_s)) if not args else _bad_args(word)
        if word == p.CMD_AVG:
            if len(args) != 1:
                return _bad_args(word)
            try:
                value = float(args[0])
            except ValueError:
                return p.format_error(p.ERR_BAD_ARGUMENT, f"AVG needs seconds; got {args[0][:20]}")
            if not 0.0 <= value <= p.MAX_AVERAGING_S:
                return p.format_error(p.ERR_OUT_OF_RANGE, f"AVG must be 0..{p.MAX_AVERAGING_S:g} s; got {args[0][:20]}")
            self._averaging_s = value
            return p.frame_reply("OK")
        if word in (p.CMD_CAP_ARM, p.CMD_CAP_COUNT, p.CMD_CAP_READ, p.CMD_CAP_BLOCK):
            return self._capture_command(word, args)
        return p.format_error(p.ERR_UNKNOWN_COMMAND, f"unknown command {word[:20]}")

    # -- on-the-fly capture (docs/interferometer-protocol.md, "On-the-fly capture") ----------------

    def trigger(self, leg: int, t_s: float) -> None:
        """A pulse on axis `leg`'s trigger input (the drive's position-compare output, through a
        drivers.sim.position_compare.TriggerLine), at `t_s`, with the plant at the crossing:
        latch a sample if the axis is armed. Called under the rig lock."""
        cap = self._capture.get(leg)
        if cap is None or len(cap[1]) >= cap[0]:
            return
        cap[1].append(self._capture_sample(leg, t_s))

    def _capture_sample(self, axis: int, t_s: float) -> tuple[str, str, str, str]:
        """(position, status, signal, t_s) texts of the reading latched at a pulse: no averaging
        (the latch is instantaneous), the plant's speed-dependent dynamics included."""
        with self._faults:
            broken = axis in self._beam_break
            nominal_pct = self._signal_pct[axis]
        plant = self.plants.get(axis)
        if plant is None or broken:
            return f"{self._last_position_mm[axis]:+.9f}", "BEAM", "0.0", f"{t_s:.6f}"
        position_mm = plant.measured_position_mm(t_s, 0.0) - self._datum_mm[axis] + self.offset_mm
        signal = float(np.clip(nominal_pct + self._rng.normal(0.0, 0.3), 0.0, 100.0))
        status = "LOW" if signal < p.LOW_SIGNAL_PCT else "OK"
        return f"{position_mm:+.9f}", status, f"{signal:.1f}", f"{t_s:.6f}"

    def _capture_command(self, word: str, args: list[str]) -> bytes:
        want = {p.CMD_CAP_ARM: 2, p.CMD_CAP_READ: 2, p.CMD_CAP_BLOCK: 3}.get(word, 1)
        if len(args) != want:
            return p.format_error(p.ERR_BAD_ARGUMENT, f"{word} takes {want} argument(s)")
        axis = self._axis(args[:1])
        if isinstance(axis, bytes):
            return axis
        try:
            number, count = (int(a) for a in (args[1:] + ["0", "0"])[:2])
        except ValueError:
            return p.format_error(p.ERR_BAD_ARGUMENT, f"{word} needs integers; got {' '.join(args[1:])[:20]}")
        with self.lock:
            cap = self._capture[axis]
            if word == p.CMD_CAP_ARM:
                if not 0 <= number <= p.MAX_CAPTURE:
                    return p.format_error(p.ERR_OUT_OF_RANGE, f"CAPARM count must be 0..{p.MAX_CAPTURE}; got {number}")
                cap[0], cap[1] = number, []
                return p.frame_reply("OK")
            if word == p.CMD_CAP_COUNT:
                return p.format_capture_count(axis, len(cap[1]), cap[0])
            if not 0 <= number < len(cap[1]):
                return p.format_error(p.ERR_OUT_OF_RANGE, f"sample {number} not captured; axis {axis} holds {len(cap[1])}")
            if word == p.CMD_CAP_BLOCK:
                if count < 1:
                    return p.format_error(p.ERR_OUT_OF_RANGE, f"CAPB? count must be >= 1; got {count}")
                return p.format_capture_block(axis, number, cap[1][number : number + count])
            return p.format_capture_sample(axis, number, *cap[1][number])

    def _axis(self, args: list[str]) -> int | bytes:
        """The axis argument, or an ERR reply."""
        if len(args) != 1:
            return p.format_error(p.ERR_BAD_ARGUMENT, "expected one axis number")
        try:
            axis = int(args[0])
        except ValueError:
            return p.format_error(p.ERR_BAD_ARGUMENT, f"axis must be an integer; got {args[0][:20]}")
        if not 1 <= axis <= self.axes:
            return p.format_error(p.ERR_BAD_AXIS, f"axis must be 1..{self.axes}; got {axis}")
        return axis

    def _position(self, axis: int) -> bytes:
        averaging_s = self._averaging_s
        # the instrument integrates over the averaging window; the lock is not held meanwhile,
        # so the simulated drive keeps running (the plant models the averaged noise)
        self.clock.sleep(averaging_s)
        with self._faults:
            broken = axis in self._beam_break
            nominal_pct = self._signal_pct[axis]
        with self.lock:
            t_s = self.clock.now()
            plant = self.plants.get(axis)
            if plant is None or broken:
                status, signal = "BEAM", 0.0
                position_mm = self._last_position_mm[axis]  # the last valid count
            else:
                position_mm = ((plant.measured_position_mm(t_s, averaging_s) - self._datum_mm[axis]) * self._air_scale(t_s)
                               + self.offset_mm)
                self._last_position_mm[axis] = position_mm
                signal = float(np.clip(nominal_pct + self._rng.normal(0.0, 0.3), 0.0, 100.0))
                status = "LOW" if signal < p.LOW_SIGNAL_PCT else "OK"
        return p.format_position(axis, position_mm, status, signal, t_s)

    def _air_now(self, t_s: float) -> tuple[float, float, float]:
        """The true air (temperature degC, pressure hPa, humidity %RH) at `t_s`: a slow wander
        (periods of an hour or two) around `air`."""
        phase = self._air_phase
        return (self.air[0] + 0.05 * math.sin(2 * math.pi * t_s / 3600.0 + phase[0]),
                self.air[1] + 0.3 * math.sin(2 * math.pi * t_s / 7200.0 + phase[1]),
                self.air[2] + 0.5 * math.sin(2 * math.pi * t_s / 5400.0 + phase[2]))

    def _air_scale(self, t_s: float) -> float:
        """Reported / true displacement: 1, unless the air sensor is off (set_air_sensor_offset)."""
        with self._faults:
            offset, index = self._air_offset_c, self._air_index
        if not offset:
            return 1.0
        t, p_hpa, h = self._air_now(t_s)
        if index is None:
            return 1.0 + 0.93e-6 * offset  # n_true / n_used, dn/dT = -0.93 ppm/K
        return float(index(t, p_hpa * 100.0, h) / index(t + offset, p_hpa * 100.0, h))

    def _environment(self) -> bytes:
        with self.lock:
            t_s = self.clock.now()
            temps = [
                self.plants[a].material_temp_c(t_s) if a in self.plants else float("nan")
                for a in range(1, self.axes + 1)
            ]
        # slow wander plus sensor noise; a faulty temperature sensor reads its offset too high
        noise = self._rng.normal(0.0, (0.002, 0.01, 0.05))
        air_c, pressure_hpa, humidity_pct = (v + n for v, n in zip(self._air_now(t_s), noise))
        with self._faults:
            air_c += self._air_offset_c
        return p.format_environment(air_c, pressure_hpa, humidity_pct, temps)


def _bad_args(word: str) -> bytes:
    return p.format_error(p.ERR_BAD_ARGUMENT, f"{word} takes no argument")
