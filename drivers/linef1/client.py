"""Client for a µLine-F1 / HPI-3D laser interferometer (implements drivers.interfaces.Interferometer).

The instrument does not answer questions: once told to, it streams distance frames (about 25 a
second) and meteo frames (about one a second per sensor), and it acknowledges each command by
echoing its code (protocol: drivers/linef1/protocol.py, docs/interferometer-protocol.md).

- A reader thread decodes the stream: it looks for the start byte, checks the CRC and the code of
  every 16-byte frame and drops what does not fit, resynchronising on the next start byte (a cut
  frame or a CRC error costs that frame; both are counted). Each distance frame becomes a sample
  time-stamped on the station's clock on arrival (frames read together are taken one stream
  period apart, the last at its arrival: the frames carry no time of their own).
- A command is written and its echo awaited `timeout_s`; not echoed, it is sent again, at most
  `retries` times, then `CommTimeout` names it.
- `read(axis)` waits the averaging time and the frame after it (on the station's clock) and
  makes the reading from the samples inside that window: mean, standard deviation and count (`StreamReading`). A sample with the small-signal
  flag (a broken beam) or an unstable laser raises `BeamBreak`; a velocity overflow raises
  `CountLost` (the count is lost: every later reading is refused until `zero` sets the origin
  again). Frames lost inside the window (CRC error, cut frame, a gap in the stream) are counted
  in `frames_lost`; fewer than half the window's samples (or none) is a `CommTimeout`.
- The distance is raw (the instrument applies no air compensation): the station divides it by
  the refractive index of the air sensor's latest values, by the equation it is given
  (procedures/metrology/air.py from the composition root), and `compensation()` says so in the
  record `station recorrect` reads (mode STATION: the index from the recorded air).
- `stream_samples(axis, t0, t1)`: the samples of a span for an on-the-fly pass, their stamps put
  on the stream's own frame grid (`_grid_stamps`: frame number x period plus the earliest
  arrival's offset ahead), which the pass aligns with the drive's traced positions
  (docs/interferometer-protocol.md, "Time stamps"). Its span cannot clear the latched
  small-signal flag as a reading's window does: after a beam break the pass's retry clears it
  first (`clear_signal_latch`).
- One beam: the instrument measures the leg it was last zeroed on (`zero(axis)`); reading
  another axis is refused.
- The protocol as publicly described has no identity query: `identity()` gives the model and
  serial the station was configured with, and says so.
"""

from __future__ import annotations

import math
import os
import select
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Callable

import serial

from drivers.clock import SystemClock
from drivers.errors import BeamBreak, CommTimeout, CountLost, DriverError
from drivers.interfaces import Clock, Environment, Reading, StreamSample
from drivers.linef1 import protocol as lf

NO_IDENTITY_QUERY = "no identity query in the protocol: model and serial as configured"
_POLL_S = 0.02
_KNOWN_CODES = frozenset((*lf.DATA_FRAMES, *lf.COMMANDS))
MAX_AVERAGING_S = 10.0
GRID_HORIZON_S = 30.0
"""How far ahead in the stream a sample's time stamp looks for the earliest arrival (`_grid_stamps`):
long enough that some frame in it arrived without delay; short enough that the instrument's and
the station's clocks (crystals within 50 ppm of each other) drift apart by at most 1.5 ms in it."""
READER_THREAD = "linef1 reader {port}"
"""The name of a client's reader thread (the thread that stamps the frames): a simulated instrument
in the same process waits for that thread's stamp (drivers/sim/linef1_server.py)."""
MIN_SAMPLE_FRACTION = 0.5
"""A window with fewer of its expected samples (averaging time / stream period) is not a reading:
`CommTimeout` (a gap in the stream), for the sweep to ask again. With more, frames lost in it only
flag the reading (`frames_lost`)."""


@dataclass(frozen=True)
class StreamReading(Reading):
    """A reading made from the streamed samples of one dwell window: `position_mm` their mean
    (air-compensated), `std_um` their standard deviation (NaN for one sample), `samples` how
    many, `frames_lost` frames the window lost (CRC error, cut frame, gap), `t_s` the last sample's
    time stamp."""

    std_um: float = math.nan
    samples: int = 0
    frames_lost: int = 0


@dataclass(frozen=True)
class _Sample:
    seq: int  # order of arrival among all frames (acks included)
    t_s: float
    raw_mm: float
    overflow: bool
    stable: bool
    signal_good: bool
    level: int
    frame_no: int = 0  # the distance frame's number in the stream, frames lost to CRC/cut counted


def linear_air_index(temp_c: float, pressure_pa: float, humidity_pct: float) -> float:
    """A stand-in index (linearised near 20 degC, 1013.25 hPa, 633 nm) for tests without the
    station's equations; the composition root passes procedures/metrology/air.py's."""
    return 1.0 + 2.7e-4 * (pressure_pa / 101325.0) * (293.15 / (273.15 + temp_c)) - 3.7e-10 * humidity_pct * 10.0


class LineF1Interferometer:
    """A µLine-F1 / HPI-3D on serial `port` (``/dev/ttyUSB0``, a pty of the simulator).

    `clock` stamps the samples and paces the averaging window (the rig's clock; default the
    system's); `timeout_s` is how long (real seconds) a command's echo, or the first sample after
    a window, is awaited; `retries` how often an unechoed command is sent again.
    `index(temp_c, pressure_pa, humidity_pct) -> n` is the refractive index of air the station
    applies, described by `equation`, `wavelength_nm` (the instrument's vacuum wavelength, not
    in the protocol: configuration) and `co2_ppm`. `material_sensors` maps a meteo sensor id to
    the leg its temperature belongs to (default: sensor n on leg n). `model`/`serial`/`vendor`
    are the configured identity. `stream_period_s` the nominal time between distance frames.
    """

    def __init__(self, port: str, baudrate: int = lf.BAUDRATE, timeout_s: float = 0.5, retries: int = 2,
                 axes: int = 6, clock: Clock | None = None,
                 index: Callable[[float, float, float], float] | None = None, equation: str = "CIDDOR",
                 wavelength_nm: float = 632.991, co2_ppm: float = 450.0,
                 material_sensors: dict[int, int] | None = None,
                 vendor: str = "Lasertex", model: str = "HPI-3D (uLine-F1)", serial_number: str = "",
                 stream_period_s: float = 1.0 / lf.STREAM_RATE_HZ, history_s: float = 120.0):
        if timeout_s <= 0 or retries < 0 or axes < 1 or stream_period_s <= 0:
            raise ValueError("timeout_s > 0, retries >= 0, axes >= 1 and stream_period_s > 0 are required")
        self.port = port
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self.axes = int(axes)
        self._clock = clock or SystemClock()
        self._index = index or linear_air_index
        self.equation = equation.upper()
        self.wavelength_nm = float(wavelength_nm)
        self.co2_ppm = float(co2_ppm)
        self._material = dict(material_sensors) if material_sensors else {n: n for n in range(1, self.axes + 1)}
        self.vendor, self.model, self.serial_number = vendor, model, serial_number
        self.period_s = float(stream_period_s)
        self._averaging_s = 0.0
        self._cv = threading.Condition()
        self._samples: deque[_Sample] = deque(maxlen=max(16, int(history_s / self.period_s)))
        self._meteo: dict[int, tuple[float, lf.MeteoFrame]] = {}
        self._acks: dict[bytes, int] = {}  # code -> seq of its latest echo
        self._seq = 0
        self._frame_no = 0  # distance frames since the stream began, lost ones included
        self._origin_seq: int | None = None  # seq of the last SET_ORIGIN echo: samples after it count
        self._losses: deque[tuple[float, int]] = deque(maxlen=4096)  # (t_s, frames) lost to CRC/cut frames
        self.crc_errors = 0  # frames dropped for their CRC or an unknown code
        self.bytes_dropped = 0  # bytes skipped while resynchronising
        self.commands_sent = 0
        self.bytes_out = 0  # bytes of the commands written
        self.bytes_in = 0  # bytes received (the streams, echoes, anything dropped)
        self.retried = 0
        self._aimed: int | None = None  # the axis the beam was zeroed on
        self.velocity_m_s: float | None = None  # the last velocity frame's (the velocity stream is not used)
        self._count_lost = False
        self._stop = threading.Event()
        self._closed = False
        self.failures: list[BaseException] = []
        try:
            self._serial = serial.Serial(port, baudrate=int(baudrate), bytesize=serial.EIGHTBITS,
                                         parity=serial.PARITY_NONE, stopbits=serial.STOPBITS_ONE,
                                         timeout=_POLL_S, write_timeout=self.timeout_s, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DriverError(f"cannot open the µLine-F1 interferometer's serial port {port!r}: {exc}",
                              hint="Check the port name (ls /dev/ttyUSB* /dev/serial/by-id) and permissions "
                                   "(group dialout).") from exc
        self._thread = threading.Thread(target=self._reader, name=READER_THREAD.format(port=port), daemon=True)
        self._thread.start()
        try:
            self._command(lf.CMD_DISTANCE_ON)
            self._command(lf.CMD_METEO_ON)
        except DriverError:
            self.close()
            raise

    # -- Interferometer interface ------------------------------------------------------------

    def identity(self) -> str:
        """'vendor,model,serial,firmware' as configured: the protocol has no identity query."""
        return f"{self.vendor},{self.model},{self.serial_number or 'not configured'},{NO_IDENTITY_QUERY}"

    def compensation(self) -> dict:
        """The session's record of the air compensation (docs/interferometer-protocol.md): the
        station applied the index itself (mode STATION) from the air sensor's values, which the
        session records at every point, so `station recorrect` can redo it."""
        return {"mode": "STATION", "equation": self.equation, "wavelength_nm": self.wavelength_nm,
                "air_temp_c": None, "air_pressure_hpa": None, "humidity_pct": None,
                "co2_ppm": self.co2_ppm, "dead_path_mm": 0.0,
                "applied_by": "the station, from the instrument's air sensor (the µLine-F1 streams raw distance)"}

    def set_averaging(self, averaging_s: float) -> None:
        """The window of each reading, seconds (0..10): its samples are averaged."""
        if not 0.0 <= averaging_s <= MAX_AVERAGING_S:
            raise ValueError(f"averaging time must be within 0..{MAX_AVERAGING_S:g} s, got {averaging_s} s")
        self._averaging_s = float(averaging_s)

    def averaging(self) -> float:
        return self._averaging_s

    def zero(self, axis: int) -> None:
        """Set the origin where the beam is now, on leg `axis` (the one beam is on it from now on);
        clears the overflow and small-signal flags first, so a lost count is recovered here."""
        axis = self._check_axis(axis)
        self._command(lf.CMD_CLEAR_OVERFLOW)
        self._command(lf.CMD_CLEAR_SMALL_SIGNAL)
        seq = self._command(lf.CMD_SET_ORIGIN)
        with self._cv:
            self._origin_seq = seq
            self._aimed = axis
            self._count_lost = False

    def clear_signal_latch(self, axis: int) -> None:
        """Clear the latched small-signal flag (drivers.interfaces.LatchingInterferometer): the
        samples after the echo judge the beam by themselves. `axis` checked; the origin and a lost
        count are untouched (only `zero` recovers those)."""
        self._check_axis(axis)
        self._command(lf.CMD_CLEAR_SMALL_SIGNAL)

    def _judge(self, samples, axis: int) -> None:
        """Every sample of a point's window or a pass's span must be good: a velocity overflow loses
        the count (CountLost, until the origin is set again), a small signal or an unstable laser is
        a beam break (BeamBreak); neither is ever averaged into a reading."""
        for s in samples:
            if s.overflow:
                with self._cv:
                    self._count_lost = True
                raise CountLost(f"µLine-F1 on {self.port}: velocity overflow on leg {axis} at t = {s.t_s:.3f} s: "
                                "the count is lost; the origin must be set again.")
            if not s.signal_good or not s.stable:
                why = "small signal (beam interrupted)" if not s.signal_good else "laser not stable"
                raise BeamBreak(f"µLine-F1 on {self.port}, leg {axis}: {why} at t = {s.t_s:.3f} s "
                                f"(signal level {s.level}).")

    def _measuring(self, axis: int) -> tuple[int, int]:
        """`axis` checked, and the stream's origin (the sequence number it was zeroed at): DriverError
        when the one beam is not zeroed on this leg, CountLost when its count was lost since."""
        axis = self._check_axis(axis)
        with self._cv:
            aimed, lost, origin = self._aimed, self._count_lost, self._origin_seq
        if aimed != axis or origin is None:
            raise DriverError(f"the µLine-F1 on {self.port} measures one beam, zeroed on "
                              f"{'no leg yet' if aimed is None else f'leg {aimed}'}; leg {axis} was not zeroed",
                              hint="Zero the laser on the leg first (the sweep does at each leg's reference).")
        if lost:
            raise CountLost(f"µLine-F1 on {self.port}: leg {axis}'s count was lost (velocity overflow); the "
                            "position is not valid until the origin is set again.")
        return axis, origin

    def read(self, axis: int) -> StreamReading:
        """The reading of `axis` over the averaging window starting now (module docstring).

        `position_mm` relative to the origin, positive = leg longer, air-compensated by the
        station; `t_s` the time stamp of the window's last sample."""
        axis, origin = self._measuring(axis)
        # The window opens with a command's echo: every frame before it in the stream was measured
        # before (the frames carry no time of their own), so none from before the dwell (e.g. the
        # leg still moving) can be mistaken for one of the window, however late it was read. The
        # command clears the latched small-signal flag: the window judges the beam by itself.
        after = max(origin, self._command(lf.CMD_CLEAR_SMALL_SIGNAL))
        t0 = self._clock.now()
        # at least one stream period: a streaming laser has no reading sooner (AVG 0 = the next sample)
        self._clock.sleep(max(self._averaging_s, self.period_s))
        t1 = self._clock.now()
        deadline = time.monotonic() + self.timeout_s
        while True:
            with self._cv:
                newest = self._samples[-1] if self._samples else None
                if newest is not None and newest.seq > after and newest.t_s >= t1:
                    break
                left = deadline - time.monotonic()
                if left <= 0 or self._closed:
                    raise CommTimeout(f"µLine-F1 on {self.port}: no distance frame for {self.timeout_s:g} s after the "
                                      f"window {t0:.3f}..{t1:.3f} s (a gap in the stream).")
                # the window's end is in: the frame after it is due a period after the newest; on
                # the station's clock, which a simulated rig's clock only passes when slept on
                ahead_s = (newest.t_s + self.period_s - self._clock.now()) if newest is not None else 0.0
                if -self.period_s < ahead_s <= 0.0 and newest is not None:
                    # due, not in: late by the transport's jitter; waited for on the station's clock
                    ahead_s = self.period_s / 8.0
                elif not 0.0 < ahead_s <= self.period_s:
                    self._cv.wait(min(left, _POLL_S))
                    continue
            self._clock.sleep(max(ahead_s, 1e-6))
        with self._cv:
            ordered = []  # the samples after the window's opening echo, in order (newest last)
            for s in reversed(self._samples):
                if s.seq <= after:
                    break
                ordered.append(s)
            ordered.reverse()
            losses = [n for t, n in self._losses if t0 - self.period_s <= t <= t1 + self.period_s]
        window = [s for s in ordered if t0 <= s.t_s <= t1] or [next(s for s in ordered if s.t_s >= t1)]
        self._judge(window, axis)
        expected = max(1, math.floor(self._averaging_s / self.period_s + 1e-9))
        if len(window) < math.ceil(MIN_SAMPLE_FRACTION * expected):
            # too little of the window left to stand for it: asked again, not averaged
            raise CommTimeout(f"µLine-F1 on {self.port}: {len(window)} of about {expected} distance frames in the window "
                              f"{t0:.3f}..{t1:.3f} s (a gap in the stream).")
        n_air = self._air_index()
        values = [s.raw_mm / n_air for s in window]
        mean = math.fsum(values) / len(values)
        std = math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (len(values) - 1)) * 1000.0 if len(values) > 1 else math.nan
        lost = max(sum(losses), self._gap_frames(ordered, window, t0))
        level = window[-1].level
        return StreamReading(axis=axis, position_mm=mean, beam_ok=True, signal_pct=round(level * 100.0 / 255.0, 1),
                             t_s=window[-1].t_s, std_um=std, samples=len(values), frames_lost=lost)

    def stream_samples(self, axis: int, t0_s: float, t1_s: float) -> list[StreamSample]:
        """The distance samples of `axis` time-stamped within `t0_s`..`t1_s` on the station's clock
        (air-compensated, relative to the origin; on-the-fly passes, docs/onthefly.md). Waits
        (`timeout_s`, real time) for a sample stamped at or after `t1_s`. A sample with the
        small-signal flag raises `BeamBreak`, a velocity overflow `CountLost`; fewer than half
        the samples the span should hold, `CommTimeout` (a gap in the stream).

        Time stamps: a sample is stamped on its arrival (frames read together one stream period
        apart, the last at its arrival): the transport's latency makes them late by a constant
        part, which an on-the-fly pass's alignment takes as part of the speed lag
        (docs/interferometer-protocol.md, "Time stamps")."""
        axis, origin = self._measuring(axis)
        deadline = time.monotonic() + self.timeout_s
        with self._cv:
            while not (self._samples and self._samples[-1].t_s >= t1_s):
                left = deadline - time.monotonic()
                if left <= 0 or self._closed:
                    raise CommTimeout(f"µLine-F1 on {self.port}: no distance frame stamped after {t1_s:.3f} s "
                                      f"within {self.timeout_s:g} s (a gap in the stream).")
                self._cv.wait(min(left, _POLL_S))
            after = [x for x in self._samples if x.seq > origin and x.t_s >= t0_s - self.period_s]
        stamps = self._grid_stamps(after)
        span = [x for x, t in zip(after, stamps) if t0_s <= t <= t1_s]
        stamps = [t for t in stamps if t0_s <= t <= t1_s]
        self._judge(span, axis)
        expected = max(1, math.floor((t1_s - t0_s) / self.period_s + 1e-9))
        if len(span) < math.ceil(MIN_SAMPLE_FRACTION * expected):
            raise CommTimeout(f"µLine-F1 on {self.port}: {len(span)} of about {expected} distance frames in "
                              f"{t0_s:.3f}..{t1_s:.3f} s (a gap in the stream).")
        n_air = self._air_index()
        return [StreamSample(t_s=t, position_mm=x.raw_mm / n_air) for x, t in zip(span, stamps)]

    def stream_arrivals(self, t0_s: float, t1_s: float) -> list[tuple[int, float]]:
        """(frame number, arrival stamp s) of the distance frames that arrived within `t0_s`..`t1_s`
        on the station's clock, unaligned (frames lost to CRC errors or cuts keep their numbers):
        the stream's arrival jitter against its own frame grid (bench/bench_latency.py)."""
        with self._cv:
            return [(x.frame_no, x.t_s) for x in self._samples if t0_s <= x.t_s <= t1_s]

    def _grid_stamps(self, samples: list[_Sample], horizon_s: float = GRID_HORIZON_S) -> list[float]:
        """The samples' times on the stream's own grid: the instrument sends a frame every
        period (its crystal), the host's arrival stamps are late by the transport, by a varying
        part on top of a constant one. A frame's time is its number times the period plus the
        smallest offset (arrival - number x period) among it and the frames after it within
        `horizon_s`: the earliest arrival bounds the latency; looking only forward, a gap in the
        stream (frames never sent, so not numbered) moves the grid of the frames after it only."""
        if not samples:
            return []
        period = self.period_s
        offsets = [x.t_s - x.frame_no * period for x in samples]
        out = [0.0] * len(samples)
        window: deque[int] = deque()  # indices, their offsets increasing: the minimum of the horizon first
        for i in range(len(samples) - 1, -1, -1):
            while window and offsets[window[-1]] >= offsets[i]:
                window.pop()
            window.append(i)
            while samples[window[0]].t_s > samples[i].t_s + horizon_s:
                window.popleft()
            out[i] = samples[i].frame_no * period + offsets[window[0]]
        return out

    def environment(self) -> Environment:
        """The air sensor's latest values and each leg's material sensor (NaN: none)."""
        air = self._air()
        temps = [math.nan] * self.axes
        with self._cv:
            meteo = dict(self._meteo)
        for sensor, leg in self._material.items():
            if sensor in meteo and 1 <= leg <= self.axes:
                temps[leg - 1] = meteo[sensor][1].temp_c
        return Environment(air_temp_c=air.temp_c, air_pressure_hpa=air.pressure_pa / 100.0,
                           humidity_pct=air.humidity_pct, material_temp_c=tuple(temps))

    def close(self) -> None:
        """Stop the streams (best effort), the reader and release the port. Safe to call twice."""
        if self._closed:
            return
        try:
            if self._serial.is_open:
                self._serial.write(lf.command_frame(lf.CMD_STREAMS_OFF))
        except (serial.SerialException, OSError):
            pass
        self._stop.set()
        with self._cv:
            self._closed = True
            self._cv.notify_all()
        # the reader notices within a poll slice; its descriptor is closed only after it ended, so
        # it can never read from a descriptor number given to another port meanwhile
        self._thread.join(timeout=10.0)
        if self._serial.is_open:
            self._serial.close()

    def __enter__(self) -> "LineF1Interferometer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals -------------------------------------------------------------------------------

    def _check_axis(self, axis: int) -> int:
        if isinstance(axis, bool) or not isinstance(axis, int) or not 1 <= axis <= self.axes:
            raise ValueError(f"interferometer axis must be an integer in 1..{self.axes}, got {axis!r}")
        return axis

    def _air(self) -> lf.MeteoFrame:
        deadline = time.monotonic() + self.timeout_s
        with self._cv:
            while lf.AIR_SENSOR_ID not in self._meteo:
                left = deadline - time.monotonic()
                if left <= 0 or self._closed:
                    raise CommTimeout(f"µLine-F1 on {self.port}: no meteo frame from the air sensor (id 0) within "
                                      f"{self.timeout_s:g} s; the station needs it to compensate for the air.",
                                      hint="Check that the environment unit's air sensor is paired and powered.")
                self._cv.wait(min(left, _POLL_S))
            return self._meteo[lf.AIR_SENSOR_ID][1]

    def _air_index(self) -> float:
        air = self._air()
        n = float(self._index(air.temp_c, air.pressure_pa, air.humidity_pct))
        if not 1.0 < n < 1.001:
            raise DriverError(f"µLine-F1 on {self.port}: the air sensor reads {air.temp_c:.2f} degC, "
                              f"{air.pressure_pa:.0f} Pa, {air.humidity_pct:.0f} %RH, an index of {n!r}: not air.",
                              hint="Check the air sensor.")
        return n

    def _command(self, code: bytes) -> int:
        """Send `code`, wait for its echo; returns the echo's arrival order (seq)."""
        name = lf.COMMANDS.get(code, code.hex())
        if self._closed:
            raise DriverError(f"µLine-F1 on {self.port} is closed", hint="Open a new connection.")
        frame = lf.command_frame(code)
        for attempt in range(self.retries + 1):
            if attempt:
                self.retried += 1
            with self._cv:
                before = self._acks.get(code, -1)
            try:
                self._serial.write(frame)
            except (serial.SerialException, OSError) as exc:
                raise DriverError(f"µLine-F1 on {self.port}: cannot write '{name}': {exc}") from exc
            self.commands_sent += 1
            self.bytes_out += len(frame)
            deadline = time.monotonic() + self.timeout_s
            with self._cv:
                while self._acks.get(code, -1) == before:
                    left = deadline - time.monotonic()
                    if left <= 0 or self._closed:
                        break
                    self._cv.wait(min(left, _POLL_S))
                else:
                    return self._acks[code]
        raise CommTimeout(f"µLine-F1 on {self.port}: '{name}' ({code[0]:02X} {code[1]:02X}) not acknowledged in "
                          f"{self.retries + 1} attempt(s) of {self.timeout_s:g} s.")

    def _reader(self) -> None:
        buf = bytearray()
        fd = self._serial.fileno() if hasattr(self._serial, "fileno") else None
        dropped = 0  # bytes skipped since the last good frame
        while not self._stop.is_set():
            try:
                if fd is not None:
                    if not select.select((fd,), (), (), _POLL_S)[0]:
                        continue
                    chunk = os.read(fd, 4096)
                else:  # pragma: no cover - non-POSIX
                    chunk = self._serial.read(max(1, self._serial.in_waiting))
            except BlockingIOError:
                continue
            except (OSError, serial.SerialException, ValueError, TypeError) as exc:
                if not self._stop.is_set():
                    self.failures.append(exc)
                with self._cv:
                    self._closed = True
                    self._cv.notify_all()
                return
            if not chunk:
                continue
            # time-stamped once read (on the simulated rig the instrument holds the clock at the
            # frame's instant until this stamp, drivers/sim/linef1_server.py)
            arrived = self._clock.now()
            self.bytes_in += len(chunk)
            buf += chunk
            frames: list[tuple[bytes, int]] = []  # (frame, frames lost just before it)
            while len(buf) >= lf.FRAME_BYTES:
                start = buf.find(lf.START)
                if start < 0:
                    dropped += len(buf)
                    buf.clear()
                    break
                if start:
                    dropped += start
                    del buf[:start]
                    continue
                frame = bytes(buf[:lf.FRAME_BYTES])
                if lf.frame_ok(frame) and frame[1:3] in _KNOWN_CODES:
                    lost = 0
                    if dropped:
                        lost = max(1, round(dropped / lf.FRAME_BYTES))
                        self.bytes_dropped += dropped
                        self.crc_errors += lost
                        dropped = 0
                    frames.append((frame, lost))
                    del buf[:lf.FRAME_BYTES]
                else:
                    dropped += 1  # resynchronise on the next start byte
                    del buf[:1]
            if frames:
                self._accept(frames, arrived)

    def _accept(self, frames: list[tuple[bytes, int]], arrived: float) -> None:
        # stream frames read together: one period apart (lost ones keep their slot), the last at its arrival
        slots, k = [], 0
        for frame, lost in reversed(frames):
            if frame[1:3] in (lf.FRAME_DISTANCE, lf.FRAME_VELOCITY):
                slots.append(k)
                k += 1 + lost
            else:
                slots.append(None)
        slots.reverse()
        with self._cv:
            last_t = self._samples[-1].t_s if self._samples else -math.inf
            for (frame, lost), slot in zip(frames, slots):
                self._seq += 1
                code, data = frame[1:3], frame[3:15]
                if code == lf.FRAME_DISTANCE or code == lf.FRAME_VELOCITY:
                    t_s = max(arrived - slot * self.period_s, last_t + 1e-9)
                    last_t = t_s
                    if lost:
                        self._losses.append((t_s, lost))
                    self._frame_no += 1 + lost
                    if code == lf.FRAME_VELOCITY:  # not asked for by the station; kept, not a position
                        self.velocity_m_s = lf.decode_velocity(data).velocity_m_s
                        continue
                    d = lf.decode_distance(data)
                    self._samples.append(_Sample(self._seq, t_s, d.distance_m * 1000.0, d.overflow, d.laser_stable,
                                                 d.signal_good, d.level, self._frame_no))
                    if d.overflow and self._origin_seq is not None:
                        self._count_lost = True  # the count is lost whenever it happens (moving or not)
                elif code == lf.FRAME_METEO:
                    if lost:
                        self._losses.append((arrived, lost))
                    m = lf.decode_meteo(data)
                    self._meteo[m.sensor_id] = (arrived, m)
                else:  # an echo
                    self._acks[code] = self._seq
            self._cv.notify_all()

    def _gap_frames(self, ordered: list[_Sample], window: list[_Sample], t0: float) -> int:
        """Frames missing between the sample before the window and the one after it (a gap in
        the stream shows as a time step of more than one period)."""
        first, last = ordered.index(window[0]), ordered.index(window[-1])
        run = ordered[max(0, first - 1): last + 2]
        lead = 0
        if first == 0:
            # nothing since the window opened for two periods or more: a sample is stamped on its
            # arrival, up to a period after it was due, so one period late is not yet a loss
            lead = max(0, math.floor((window[0].t_s - t0) / self.period_s + 1e-9) - 1)
        return lead + sum(max(0, round((b.t_s - a.t_s) / self.period_s) - 1) for a, b in zip(run, run[1:]))
