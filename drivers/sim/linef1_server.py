"""A simulated µLine-F1 / HPI-3D laser interferometer on a real pseudo-terminal.

It speaks the streaming protocol of drivers/linef1/protocol.py (docs/interferometer-protocol.md,
"The µLine-F1 protocol") on the master side of a pty: it echoes every well-formed command, and
once told to, streams a distance frame every `period_s` and, each second, a meteo frame of the
air sensor (id 0) and of each leg's material sensor (id = leg) -- on the rig's clock, which may be
virtual. Distances are raw: the true displacement of the leg the beam is on (`LegPlant`, the
same plant the simulated drive moves) times the refractive index of the true air, since the
origin was set; the station divides by the index of what the air sensor reports.

One beam: it is on the leg that was enabled when the origin was last set (`aim()`, wired by the
simulated rig to the drives: the operator sets the laser up on the leg being prepared).

Virtual time: frames are due at multiples of `period_s`; the serving thread wakes every
`poll_s` real seconds and writes every frame due since the last, in time order (frames older than
`max_catch_up_s` before now are skipped then; the plant read once for the frames written together,
each with a noise draw of its own). With `sync` (the rig's drives) on a clock with event stops at
time scale 0 (drivers.clock.VirtualClock.add_events) the instrument is deterministic for a seed
instead: the clock stops at every frame's instant (distance and meteo), the drive is brought there
(`sync`), the frame written then, in the thread advancing the clock, and the clock held there until
the client has time-stamped it (`_wait_stamped`): a move made within one jump yields samples along
its path at their own times, and every sample's stamp is its instant. The serving thread then
only answers commands: a frame it wrote could see the leg where the drive was last brought (on a
pass 10 ms of travel stale, 0.2 mm at 20 mm/s: a pass read hundreds of um off), and the moments it
wakes (real time) would decide which frames are skipped, stamped late or which noise they draw.

Faults on demand (`inject`): CRC errors, cut frames, a gap in the stream, a broken beam (small
signal, latched until cleared), a velocity overflow (latched; the count is lost until the origin
is set again), commands not echoed. `at_rest_after_s` places a fault that long after the beam's
leg next comes to rest (a point's dwell and window), else it starts with the next frame.
"""

from __future__ import annotations

import math
import os
import select
import fcntl
import struct
import termios
import threading
import time
from collections import Counter
from dataclasses import dataclass
from typing import Callable

import numpy as np

from drivers.interfaces import Clock
from drivers.linef1 import protocol as lf
from drivers.linef1.client import READER_THREAD
from drivers.plant.leg import LegPlant
from drivers.sim.pty_server import PtyServer

FAULT_KINDS = ("crc", "cut", "gap", "beam", "overflow", "no_ack")
TRACED = 2
"""`sync(leg)`'s answer for a move the host traces (the drive's, drivers/sim/drive_server.py)."""
LOST_COUNT_MM = 0.3172  # where a lost count leaves the reading: off by a whole number of fringes, far from right


def linear_index(temp_c: float, pressure_pa: float, humidity_pct: float) -> float:
    """Refractive index of air near 20 degC / 1013.25 hPa / 633 nm, linearised (used when the
    rig gives no equation: drivers do not import procedures)."""
    return 1.0 + 2.7e-4 * (pressure_pa / 101325.0) * (293.15 / (273.15 + temp_c)) - 3.7e-9 * humidity_pct


@dataclass
class _Fault:
    kind: str
    frames: int  # frames it lasts (crc, cut, overflow: 1 frame sets the latch)
    duration_s: float  # virtual seconds it lasts (gap, beam)
    at_rest_after_s: float | None
    armed_rest_s: float  # the rest time seen when armed: the fault waits for a later one
    start_s: float | None = None


class SimLineF1(PtyServer):
    """Simulated µLine-F1. `plants`: leg -> plant; `aim()` -> the leg the beam is set up on when
    the origin is set (None: keep the last); `index(temp_c, pressure_pa, humidity_pct)` the air's
    refractive index (the station's equation from the composition root, else linearised);
    `air` (temp degC, pressure hPa, humidity %RH) the air the sensors wander around."""

    name = "sim-linef1"

    def __init__(self, plants: dict[int, LegPlant], clock: Clock, lock: threading.RLock | None = None,
                 aim: Callable[[], int | None] | None = None, index: Callable[[float, float, float], float] | None = None,
                 air: tuple[float, float, float] = (20.0, 1013.25, 45.0), seed: int = 0, offset_um: float = 0.0,
                 period_s: float = 1.0 / lf.STREAM_RATE_HZ, max_catch_up_s: float = 2.0, poll_s: float = 0.002,
                 sensor_noise: bool = True, sync: Callable[[int], bool] | None = None,
                 latency_s: float = 0.0, jitter_s: float = 0.0):
        if latency_s < 0 or jitter_s < 0:
            raise ValueError(f"the simulated laser's latency and jitter must be >= 0 s, got {latency_s}, {jitter_s}")
        self.plants = dict(plants)
        self.clock = clock
        self.lock = lock if lock is not None else threading.RLock()
        self._aim = aim or (lambda: min(self.plants) if self.plants else None)
        self.index = index or linear_index
        self.air = tuple(float(v) for v in air)
        self.offset_mm = 1e-3 * float(offset_um)
        self.period_s = float(period_s)
        self.max_catch_up_s = float(max_catch_up_s)
        self.poll_s = float(poll_s)
        self._rng = np.random.default_rng(seed + 4242)  # the distance frames' signal level
        self._air_phase = self._rng.uniform(0, 2 * math.pi, size=3)
        self._seed = int(seed)  # the air sensor's noise: drawn from the meteo frame's time (`_meteo`)
        self.leg: int | None = None  # the leg the beam is on
        self._datum_mm = 0.0  # plant position at the origin
        self._n0 = 1.0
        self._distance_on = self._meteo_on = False
        self._next_t: float | None = None
        self._next_meteo_t: float | None = None
        self._last_raw_m = 0.0
        self._small_signal = False  # latched until CLEAR_SMALL_SIGNAL
        self._overflow = False  # latched until CLEAR_OVERFLOW
        self._count_lost = False  # until SET_ORIGIN
        self._faults: list[_Fault] = []
        self.sensor_noise = bool(sensor_noise)  # the air sensor's noise (off: tests comparing two sessions)
        self._air_offset_c = 0.0  # set_air_sensor_offset: a faulty air temperature sensor
        self._fault_lock = threading.Lock()
        self.commands: Counter = Counter()  # command code (hex) -> times received
        self.sent = Counter()  # "distance", "meteo", "ack", "crc", "cut", "gap" -> frames
        self.failures: list[BaseException] = []
        # rig hook: sync(leg) brings the leg's drive up to the clock's now: 0 at rest, 1 moving,
        # TRACED moving in a move the host traces
        self.sync = sync
        self._events_added = False
        self._unread = False  # the client did not read what was written (not waited on then)
        # the transport's delay (bench/bench_latency.py): a batch of frames measured at its instant
        # leaves `latency_s` later, plus a uniform 0..`jitter_s` of its own, in order (a serial
        # line never overtakes); time scale 0 only (`_on_due`), echoes are not delayed
        self.latency_s, self.jitter_s = float(latency_s), float(jitter_s)
        self._jitter_rng = np.random.default_rng(seed + 4244)
        self._outbox: list[tuple[float, bytes]] = []  # (write time, frames) measured, not yet sent
        self._init_pty()

    # -- faults ---------------------------------------------------------------------------------
    def inject(self, kind: str, *, frames: int = 1, duration_s: float = 0.0, at_rest_after_s: float | None = None) -> None:
        """A fault: "crc" (the next `frames` distance frames with a wrong CRC), "cut" (cut after 8
        bytes), "gap" (no frame at all for `duration_s`), "beam" (small signal for `duration_s`,
        latched until the host clears it), "overflow" (velocity overflow: latched, and the count
        lost until the origin is set again), "no_ack" (the next `frames` commands not echoed).
        `at_rest_after_s`: start that long after the beam's leg next comes to rest."""
        if kind not in FAULT_KINDS:
            raise ValueError(f"fault kind must be one of {FAULT_KINDS}, got {kind!r}")
        with self.lock:
            rest = self._rest_since()
        with self._fault_lock:
            self._faults.append(_Fault(kind, int(frames), float(duration_s), at_rest_after_s,
                                       rest if rest is not None else -math.inf))

    def _rest_since(self) -> float | None:
        plant = self.plants.get(self.leg) if self.leg is not None else None
        if plant is None or getattr(plant, "velocity_mm_s", 0.0):
            return None
        # the plant's last stop (its ring-out start): the drive reports arrivals there
        return float(getattr(plant, "_ring", (-math.inf,))[0])

    def _active(self, kind: str, t_s: float, rest: float | None) -> _Fault | None:
        """The fault of `kind` acting on a frame due at `t_s` (starting it when due), else None."""
        with self._fault_lock:
            for f in self._faults:
                if f.kind != kind:
                    continue
                if f.start_s is None:
                    if f.at_rest_after_s is None:
                        f.start_s = t_s
                    elif rest is not None and rest > f.armed_rest_s and t_s >= rest + f.at_rest_after_s:
                        f.start_s = t_s
                    else:
                        continue
                if kind in ("gap", "beam"):
                    if t_s < f.start_s + f.duration_s:
                        return f
                    self._faults.remove(f)
                    return None
                f.frames -= 1
                if f.frames <= 0:
                    self._faults.remove(f)
                return f
        return None

    def set_air_sensor_offset(self, temp_offset_c: float) -> None:
        """A faulty air sensor reading `temp_offset_c` too high: the meteo frames report it, the
        raw distances do not change (they follow the true air), so the station's index is off."""
        self._air_offset_c = float(temp_offset_c)

    def pending_faults(self) -> int:
        with self._fault_lock:
            return len(self._faults)

    # -- serving ----------------------------------------------------------------------------------
    def _serve(self) -> None:
        pending = bytearray()
        while True:
            streaming = self._distance_on or self._meteo_on
            ready, _, _ = select.select([self._master, self._wake_r], [], [], self.poll_s if streaming else None)
            if self._wake_r in ready:
                return
            try:
                data = os.read(self._master, 4096) if self._master in ready else b""
            except BlockingIOError:
                data = b""
            # computed and written under the rig lock: frames written along a move (`_on_due`,
            # in the thread advancing the clock) and these leave in time order
            with self.lock:
                out = bytearray()
                try:
                    if not self._timed():  # (else `_on_due` writes every frame at its instant)
                        out += self._due_frames()  # first what was due before these commands arrived
                    if data:
                        pending += data
                        out += self._commands(pending)
                except Exception as exc:  # keep serving; tests check `failures` stays empty
                    self.failures.append(exc)
                self._send(bytes(out))

    def _send(self, data: bytes) -> None:
        """Write to the line without blocking: what the line cannot take (nobody reading the
        port) is lost, as on a serial line whose receiver overflows."""
        view = memoryview(data)
        while view:
            try:
                view = view[os.write(self._master, view):]
            except BlockingIOError:
                self.sent["overrun_bytes"] += len(view)
                return

    # -- virtual time: frames along a move (time scale 0) --------------------------------------------
    def start(self) -> str:
        port = super().start()
        os.set_blocking(self._master, False)
        add_events = getattr(self.clock, "add_events", None)
        if add_events is not None and self.sync is not None and not self._events_added:
            add_events(self._next_due, self._on_due)
            self._events_added = True
        return port

    def _timed(self) -> bool:
        """Whether every frame is written at its instant by `_on_due` (a clock with event stops
        at time scale 0, the rig's drives to sync): the serving thread then writes none."""
        return self._events_added and getattr(self.clock, "time_scale", 1.0) == 0

    def _next_due(self) -> float | None:
        """The clock's next stop for this instrument (drivers.clock.VirtualClock.add_events): the
        next distance frame or meteo set, while its stream is on."""
        if self._thread is None:
            return None
        due = []
        if self._distance_on and self._next_t is not None:
            due.append(self._next_t)
        if self._meteo_on and self._next_meteo_t is not None:
            due.append(self._next_meteo_t)
        if self._outbox:
            due.append(self._outbox[0][0])
        return min(due) if due else None

    def _on_due(self, t_s: float) -> None:
        """At a frame's time, within a jump of the virtual clock: the beam's leg's drive is brought
        to this instant (`sync`), the frames due are written now, and the clock is held here until
        the client has time-stamped them (`_wait_stamped`): every frame is measured and stamped at
        its own instant, whichever thread advances the clock (the host's, or the drive's in a move
        made within one request), however the threads are scheduled."""
        if self._thread is None:
            return
        with self.lock:
            if self.leg is not None and self.sync is not None:
                self.sync(self.leg)
            frames = self._due_frames()
            if frames and (self.latency_s > 0 or self.jitter_s > 0):
                # measured now, written later (the transport): at least after the batch before
                at = t_s + self.latency_s + (float(self._jitter_rng.uniform(0.0, self.jitter_s)) if self.jitter_s else 0.0)
                self._outbox.append((max(at, self._outbox[-1][0] if self._outbox else at), frames))
                frames = b""
            while self._outbox and self._outbox[0][0] <= t_s:
                frames += self._outbox.pop(0)[1]
            if not frames:
                return
            mark = self.clock.reads()
            self._send(frames)
        self._wait_stamped(mark)

    def _wait_stamped(self, mark: int, timeout_s: float = 5.0) -> None:
        """Until the client's reader thread (drivers.linef1.client.READER_THREAD, on this port)
        has read everything written and asked the clock the time since `mark` (it stamps what it
        reads on arrival), at most `timeout_s` real seconds (a loaded machine can starve it for a
        while: given up too soon, a pass's frames are all stamped late); a client that does not
        read is not waited on again until it has read everything (nothing left on the line).
        Another thread asking the time does not count (it did: the clock went on, frames were
        stamped late, a pass read tens of um off; seen in the bench on a loaded machine, and with
        a thread that asks the time every 0.2 ms, tests/drivers/test_linef1_stamps.py). A client
        of another kind (no such thread): any thread but this one and the serving one."""
        if getattr(self.clock, "read_since", None) is None:
            return
        if self._unread:
            if self._queued():
                return
            self._unread = False
        reader = self._reader_ident()
        if reader is not None:
            def stamped() -> bool:
                return self.clock.read_by(mark, reader) and not self._queued()
        else:
            exclude = {threading.get_ident(), self._thread.ident if self._thread else 0}

            def stamped() -> bool:
                return self.clock.read_since(mark, exclude)
        deadline = time.monotonic() + timeout_s
        while not stamped():
            if time.monotonic() > deadline:
                self._unread = True
                return
            time.sleep(20e-6)

    def _reader_ident(self) -> int | None:
        """The thread id of the client's reader on this port, if it runs in this process."""
        name = READER_THREAD.format(port=self.port)
        cached = getattr(self, "_reader", None)
        if cached is not None and cached.is_alive() and cached.name == name:
            return cached.ident
        self._reader = next((t for t in threading.enumerate() if t.name == name), None)
        return self._reader.ident if self._reader is not None else None

    def _queued(self) -> int:
        """Bytes written that the client has not read yet (the pty's input queue)."""
        return struct.unpack("i", fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0"))[0]

    def _commands(self, pending: bytearray) -> bytes:
        out = bytearray()
        while len(pending) >= lf.COMMAND_BYTES:
            start = pending.find(lf.START)
            if start < 0:
                pending.clear()
                break
            del pending[:start]
            if len(pending) < lf.COMMAND_BYTES:
                break
            try:
                code = lf.check_command(bytes(pending[:lf.COMMAND_BYTES]))
            except lf.LineF1Error:
                del pending[:1]  # not a command: look for the next start byte
                continue
            del pending[:lf.COMMAND_BYTES]
            self.commands[code.hex()] += 1
            if code not in lf.COMMANDS:
                continue  # unknown: not echoed (the public client would time out on it)
            if self._active("no_ack", self.clock.now(), None) is not None:
                continue
            out += lf.ack_frame(code)
            self.sent["ack"] += 1
            self._apply(code)
            if code == lf.CMD_METEO_ON:  # a first set at once (`_on_due` writes only at the clock's stops)
                out += self._due_frames()
        return bytes(out)

    def _apply(self, code: bytes) -> None:
        now = self.clock.now()
        if code == lf.CMD_DISTANCE_ON:
            # the first frame after now: the clock stops there (`_next_due`)
            t = self._grid(now)
            self._distance_on, self._next_t = True, t + self.period_s if t <= now else t
        elif code in (lf.CMD_DISTANCE_OFF, lf.CMD_VELOCITY_ON, lf.CMD_VELOCITY_OFF):
            self._distance_on = False  # velocity frames are not simulated
        elif code == lf.CMD_METEO_ON:
            self._meteo_on, self._next_meteo_t = True, now  # a first set at once, then each second
        elif code == lf.CMD_METEO_OFF:
            self._meteo_on = False
        elif code == lf.CMD_STREAMS_OFF:
            self._distance_on = self._meteo_on = False
        elif code == lf.CMD_CLEAR_SMALL_SIGNAL:
            self._small_signal = False
        elif code == lf.CMD_CLEAR_OVERFLOW:
            self._overflow = False
        elif code == lf.CMD_SET_ORIGIN:
            with self.lock:
                leg = self._aim()
                if leg is not None:
                    self.leg = leg
                plant = self.plants.get(self.leg) if self.leg is not None else None
                if plant is not None:
                    # as the station's own simulated laser: the plant forgets its error offset here
                    plant.zero_here(now)
                    self._datum_mm = plant.x_mm
                self._n0 = self._n_true(now)
            self._count_lost = False
            self._last_raw_m = 0.0

    def _grid(self, t_s: float) -> float:
        return math.ceil(t_s / self.period_s - 1e-9) * self.period_s

    def _due_frames(self) -> bytes:
        """The frames due since the last written, up to now (call under the lock)."""
        now = self.clock.now()
        out = bytearray()
        if self._distance_on and self._next_t is not None:
            if self._next_t < now - self.max_catch_up_s:
                self._next_t = self._grid(now - self.max_catch_up_s)
            due = []
            while self._next_t <= now:
                due.append(self._next_t)
                self._next_t += self.period_s
            if due:
                out += self._distances(due)
        if self._meteo_on and self._next_meteo_t is not None:
            if self._next_meteo_t < now - self.max_catch_up_s:
                self._next_meteo_t = math.floor(now)
            while self._next_meteo_t <= now:
                out += self._meteo(self._next_meteo_t)
                self._next_meteo_t = math.floor(self._next_meteo_t) + 1.0
        return bytes(out)

    def _distances(self, times_s: list[float]) -> bytes:
        """The frames due at `times_s`: the plant read once for the batch (drivers.plant.leg
        LegPlant.measured_positions_mm), each frame with its own noise and faults."""
        with self.lock:
            plant = self.plants.get(self.leg) if self.leg is not None else None
            measured = plant.measured_positions_mm(times_s) if plant is not None else [0.0] * len(times_s)
            return b"".join(self._distance(t, float(m)) for t, m in zip(times_s, measured))

    def _distance(self, t_s: float, measured_mm: float) -> bytes:
        with self.lock:
            rest = self._rest_since()
            if self._active("gap", t_s, rest) is not None:
                self.sent["gap"] += 1
                return b""
            if self._active("beam", t_s, rest) is not None:
                self._small_signal = True
            if self._active("overflow", t_s, rest) is not None:
                self._overflow = self._count_lost = True
            plant = self.plants.get(self.leg) if self.leg is not None else None
            good = plant is not None and not self._small_signal  # no leg set up yet: no signal
            if good:
                disp_mm = measured_mm - self._datum_mm + self.offset_mm
                if self._count_lost:
                    disp_mm += LOST_COUNT_MM
                # raw optical distance since the origin: n L (the index's change times the zero's
                # dead path of 0), as the instrument counts it
                self._last_raw_m = disp_mm * 1e-3 * self._n_true(t_s)
            level = int(np.clip(200 + self._rng.normal(0.0, 2.0), 0, 255)) if good else 3
            frame = lf.distance_frame(self._last_raw_m, overflow=self._overflow, laser_stable=True,
                                      signal_good=good, level=level)
            crc = self._active("crc", t_s, rest) is not None
            cut = not crc and self._active("cut", t_s, rest) is not None
        if crc:
            self.sent["crc"] += 1
            return frame[:-1] + bytes([frame[-1] ^ 0x5A])
        if cut:
            self.sent["cut"] += 1
            return frame[:8]
        self.sent["distance"] += 1
        return frame

    def air_now(self, t_s: float) -> tuple[float, float, float]:
        """The true air at `t_s`: temperature degC, pressure hPa, humidity %RH (a slow wander)."""
        ph = self._air_phase
        return (self.air[0] + 0.05 * math.sin(2 * math.pi * t_s / 3600.0 + ph[0]),
                self.air[1] + 0.3 * math.sin(2 * math.pi * t_s / 7200.0 + ph[1]),
                self.air[2] + 0.5 * math.sin(2 * math.pi * t_s / 5400.0 + ph[2]))

    def _n_true(self, t_s: float) -> float:
        temp_c, p_hpa, h = self.air_now(t_s)
        return float(self.index(temp_c, p_hpa * 100.0, h))

    def _meteo(self, t_s: float) -> bytes:
        temp_c, p_hpa, h = self.air_now(t_s)
        # drawn from the frame's time: the same values however many sets were skipped before it
        rng = np.random.default_rng((self._seed + 4243, int(round(t_s * 1000.0))))
        noise = rng.normal(0.0, (0.002, 0.01, 0.05)) if self.sensor_noise else np.zeros(3)
        out = bytearray(lf.meteo_frame(lf.AIR_SENSOR_ID, temp_c + noise[0] + self._air_offset_c, h + noise[2],
                                       (p_hpa + noise[1]) * 100.0))
        with self.lock:
            for leg, plant in sorted(self.plants.items()):
                out += lf.meteo_frame(leg, plant.material_temp_c(t_s))
        self.sent["meteo"] += 1 + len(self.plants)
        return bytes(out)
