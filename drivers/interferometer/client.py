"""Client for the serial laser interferometer (implements drivers.interfaces.Interferometer).

One command, one reply line (protocol: docs/interferometer-protocol.md). Every reply is checked
(terminator, checksum, field count and types, that it answers the question asked); a malformed
or missing reply is retried after flushing the input, at most `retries` times, then raised as
`FramingError` or `CommTimeout`. An `ERR` reply is raised at once as `InstrumentError` and a
beam status other than OK as `BeamBreak`: retrying those is the caller's decision.
"""

from __future__ import annotations

import numbers
import os
import select
import time
from urllib.parse import parse_qs, urlparse

import serial

from drivers.clock import SystemClock
from drivers.errors import BeamBreak, CommTimeout, DriverError, FramingError
from drivers.interfaces import Clock, Environment, Reading
from drivers.interferometer import protocol as p

_POLL_S = 0.02  # longest blocking read: bounds how late a deadline is noticed
_POSIX_SERIAL = getattr(serial, "Serial", None) if os.name == "posix" else None  # pyserial's serialposix.Serial
try:  # pyserial's POSIX backend raises termios.error from tcflush on a port that went away
    import termios

    _PORT_GONE: tuple[type[BaseException], ...] = (serial.SerialException, OSError, termios.error)
except ImportError:  # pragma: no cover - Windows
    _PORT_GONE = (serial.SerialException, OSError)


class SerialInterferometer:
    """A multi-axis laser interferometer on a serial port; axis n measures leg n.

    `port` is a device path (``/dev/ttyUSB0``, a pty path from the simulator, ``COM3``);
    `baudrate` in baud (8N1); `timeout_s` is the wait for one complete reply line, seconds (a
    position query waits `timeout_s` plus the averaging time); `retries` is how many times a
    missing or malformed reply is asked again; `axes` the instrument's axis count. `clock`
    measures the reply timeouts (default: the system's monotonic clock; a replay gives its
    `drivers.replay.TimeoutClock`, on which a replayed silence ends at once).

    Timing guarantee: a silent port raises `CommTimeout` after
    ``(timeout_s + averaging_s) * (retries + 1)`` seconds (averaging_s = 0 except for a
    position query) on `clock`, plus at most 20 ms per attempt (the read poll slice); a port
    that only returns garbage raises `FramingError` within the same bound, usually at once.

    The port is opened with an exclusive (advisory) lock where the platform supports it, so two
    programs cannot talk to one instrument at once. Not thread-safe: one owner at a time.
    `transactions` counts command/reply exchanges sent (retries included), for benchmarks;
    `bytes_out` / `bytes_in` the bytes of the commands sent and the reply lines received.
    """

    def __init__(
        self,
        port: str,
        baudrate: int = p.DEFAULT_BAUDRATE,
        timeout_s: float = 0.5,
        retries: int = 2,
        axes: int = 6,
        clock: Clock | None = None,
    ):
        if timeout_s <= 0:
            raise ValueError(f"interferometer timeout_s must be > 0 seconds, got {timeout_s}")
        if retries < 0:
            raise ValueError(f"interferometer retries must be >= 0, got {retries}")
        if axes < 1:
            raise ValueError(f"interferometer axes must be >= 1, got {axes}")
        self.port = port
        self.baudrate = int(baudrate)
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self.axes = int(axes)
        self._clock = clock or SystemClock()
        self.transactions = 0
        self.bytes_out = 0
        self.bytes_in = 0
        self.retried = 0  # exchanges that had to be asked again (noise statistics)
        self.reopened = 0  # times the port was opened again after it went away (unplugged)
        self._closed = False  # closed by the owner (a port that went away is reopened instead)
        self._averaging_s: float | None = None  # unknown until set or asked
        self.capture_block = True  # read captures in blocks (CAPB?) until the instrument says it has none
        try:
            self._serial = serial.Serial(
                port,
                baudrate=self.baudrate,
                bytesize=serial.EIGHTBITS,
                parity=serial.PARITY_NONE,
                stopbits=serial.STOPBITS_ONE,
                timeout=min(self.timeout_s, _POLL_S),
                write_timeout=self.timeout_s,
                exclusive=True,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            busy = "lock" in str(exc).lower() or "busy" in str(exc).lower()
            raise DriverError(
                f"cannot open the interferometer serial port {port!r}: {exc}",
                hint=(
                    "Another program holds the port; close it first."
                    if busy
                    else "Check the port name (ls /dev/ttyUSB* /dev/serial/by-id) and permissions (group dialout)."
                ),
            ) from exc

    @classmethod
    def from_url(cls, url: str) -> "SerialInterferometer":
        """Open from ``serial:///dev/pts/5?baud=115200&timeout_s=0.5&retries=2&axes=6``.

        Query parameters are optional; unknown ones are refused with a message naming them.
        """
        parsed = urlparse(url)
        port = parsed.path or parsed.netloc  # serial:///dev/ttyUSB0 or serial://COM3
        if parsed.scheme != "serial" or not port:
            raise ValueError(f"interferometer URL {url!r} must look like serial:///dev/ttyUSB0?baud=115200")
        known = {"baud": int, "timeout_s": float, "retries": int, "axes": int}
        kwargs: dict[str, object] = {}
        for key, values in parse_qs(parsed.query, strict_parsing=False).items():
            if key not in known:
                raise ValueError(f"interferometer URL {url!r}: unknown parameter {key!r}; known: {', '.join(known)}")
            try:
                kwargs["baudrate" if key == "baud" else key] = known[key](values[-1])
            except ValueError:
                raise ValueError(f"interferometer URL {url!r}: {key}={values[-1]!r} is not a number") from None
        return cls(port, **kwargs)  # type: ignore[arg-type]

    # -- Interferometer interface ------------------------------------------------------------

    def identity(self) -> str:
        """Instrument identity 'vendor,model,serial,firmware' (the *IDN? reply)."""
        return self._transact(p.cmd_identity(), p.parse_identity)

    def read(self, axis: int) -> Reading:
        """One position reading of `axis` (1..axes).

        `position_mm` is relative to the axis zero, air-compensated, positive = leg longer.
        `t_s` is the instrument's time of the reading (end of the averaging window), seconds.
        Raises `BeamBreak` when the instrument reports the beam interrupted (BEAM) or its
        signal too weak (LOW); no retry is made for that.
        """
        axis = self._check_axis(axis)
        if self._averaging_s is None:
            self._averaging_s = self._transact(p.cmd_averaging_query(), p.parse_averaging)
        reply = self._transact(
            p.cmd_position(axis), lambda fields: p.parse_position(fields, axis), extra_wait_s=self._averaging_s
        )
        if reply.status != "OK":
            why = "beam interrupted" if reply.status == "BEAM" else "signal too weak"
            raise BeamBreak(
                f"interferometer axis {axis} on {self.port}: {why} "
                f"(status {reply.status}, signal {reply.signal_pct:.1f} %, at t = {reply.t_s:.3f} s)."
            )
        return Reading(
            axis=axis, position_mm=reply.position_mm, beam_ok=True, signal_pct=reply.signal_pct, t_s=reply.t_s
        )

    def compensation(self) -> dict:
        """How the instrument compensates its readings for the air (COMP?): mode, equation,
        vacuum wavelength, the air values of a MANUAL compensation, CO2, dead path; as the JSON
        record a session stores (docs/interferometer-protocol.md, "Air compensation")."""
        return self._transact(p.cmd_compensation(), p.parse_compensation).to_json()

    def environment(self) -> Environment:
        """Air temperature (C), pressure (hPa), humidity (%RH) and material temperature per
        leg (C, index 0 = leg 1, NaN = no sensor on that axis)."""
        env = self._transact(p.cmd_environment(), lambda fields: p.parse_environment(fields, self.axes))
        return Environment(
            air_temp_c=env.air_temp_c,
            air_pressure_hpa=env.air_pressure_hpa,
            humidity_pct=env.humidity_pct,
            material_temp_c=env.material_temp_c,
        )

    def zero(self, axis: int) -> None:
        """Set the zero of `axis` at its current position (later readings are relative to it)."""
        axis = self._check_axis(axis)
        self._transact(p.cmd_zero(axis), p.parse_ok)

    def set_averaging(self, averaging_s: float) -> None:
        """Averaging time of each position reading, seconds (0..10). Longer = less noise; a
        position query then takes that much longer to answer."""
        if not 0.0 <= averaging_s <= p.MAX_AVERAGING_S:
            raise ValueError(f"averaging time must be within 0..{p.MAX_AVERAGING_S:g} s, got {averaging_s} s")
        self._transact(p.cmd_set_averaging(averaging_s), p.parse_ok)
        self._averaging_s = float(p.format_averaging(averaging_s))

    def averaging(self) -> float:
        """The instrument's current averaging time, seconds (asks it)."""
        self._averaging_s = self._transact(p.cmd_averaging_query(), p.parse_averaging)
        return self._averaging_s

    def close(self) -> None:
        """Release the port. Safe to call twice."""
        self._closed = True
        if self._serial.is_open:
            self._serial.close()

    def __enter__(self) -> "SerialInterferometer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- on-the-fly capture (docs/interferometer-protocol.md, "On-the-fly capture") ---------------
    def arm_capture(self, axis: int, count: int) -> None:
        """Clear `axis`'s capture buffer and latch a reading at each of the next `count`
        trigger pulses (the drive's position-compare output)."""
        axis = self._check_axis(axis)
        if not 0 <= int(count) <= p.MAX_CAPTURE:
            raise ValueError(f"capture count must be within 0..{p.MAX_CAPTURE}, got {count}")
        self._transact(p.cmd_capture_arm(axis, count), p.parse_ok)

    def capture_count(self, axis: int) -> tuple[int, int]:
        """(samples captured, samples armed) of `axis`."""
        axis = self._check_axis(axis)
        return self._transact(p.cmd_capture_count(axis), lambda f: p.parse_capture_count(f, axis))

    def capture_samples(self, axis: int, start: int, count: int) -> list[Reading]:
        """Samples `start` .. `start + count - 1` of `axis`'s capture, as `capture_sample` gives
        them (BeamBreak at the first one taken without beam), read in blocks (`CAPB?`: as many
        samples per exchange as fit in one reply line, about five) where the instrument has
        the command, else one per exchange (`CAP?`; an instrument answering `CAPB?` as an
        unknown command is asked that way from then on)."""
        axis = self._check_axis(axis)
        out: list[Reading] = []
        i, end = int(start), int(start) + int(count)
        while i < end:
            if not self.capture_block:
                out.append(self.capture_sample(axis, i))
                i += 1
                continue
            try:
                block = self._transact(p.cmd_capture_block(axis, i, end - i),
                                       lambda f, i=i: p.parse_capture_block(f, axis, i, end - i))
            except p.InstrumentError as exc:
                if exc.code != p.ERR_UNKNOWN_COMMAND:
                    raise
                self.capture_block = False
                continue
            for s in block:
                out.append(self._capture_reading(s))
            i += len(block)
        return out

    def _capture_reading(self, s: p.CaptureSample) -> Reading:
        if s.status != "OK":
            why = "beam interrupted" if s.status == "BEAM" else "signal too weak"
            raise BeamBreak(f"interferometer axis {s.axis} on {self.port}: {why} at capture sample {s.index} "
                            f"(status {s.status}, signal {s.signal_pct:.1f} %, at t = {s.t_s:.3f} s).")
        return Reading(axis=s.axis, position_mm=s.position_mm, beam_ok=True, signal_pct=s.signal_pct, t_s=s.t_s)

    def capture_sample(self, axis: int, index: int) -> Reading:
        """Sample `index` (0-based) of `axis`'s capture. `t_s` is the instrument time of the
        trigger pulse. BeamBreak when the beam was interrupted or weak at that pulse."""
        axis = self._check_axis(axis)
        s = self._transact(p.cmd_capture_read(axis, index), lambda f: p.parse_capture_sample(f, axis, int(index)))
        return self._capture_reading(s)


    # -- one exchange ------------------------------------------------------------------------

    def _check_axis(self, axis: int) -> int:
        if type(axis) is int and 1 <= axis <= self.axes:  # the usual case, without the ABC check
            return axis
        if isinstance(axis, bool) or not isinstance(axis, numbers.Integral) or not 1 <= axis <= self.axes:
            raise ValueError(f"interferometer axis must be an integer in 1..{self.axes}, got {axis!r}")
        return int(axis)

    def _transact(self, command: bytes, parse, extra_wait_s: float = 0.0):
        """Send `command`, read one reply line, check and `parse` its fields; retry on
        missing or malformed replies. Returns what `parse` returns."""
        if self._closed:
            raise DriverError(f"interferometer on {self.port} is closed", hint="Open a new connection.")
        shown = command.decode("ascii").strip()
        wait_s = self.timeout_s + extra_wait_s
        last_problem: tuple[str, bytes] | None = None  # (reason, line) of the last malformed reply
        gone: BaseException | None = None  # why the port failed on the last attempt, if it did
        timeouts = 0
        for attempt in range(self.retries + 1):
            if attempt:
                self.retried += 1
            gone = None
            try:
                if not self._serial.is_open and not self._reopen(self._clock.now() + wait_s):
                    raise serial.SerialException(f"{self.port} is not there")
                # drop anything unsolicited (the rest of a garbled line, a reply that came too
                # late) so it cannot pass for the answer to this command
                self._serial.reset_input_buffer()
                self.transactions += 1
                # the deadline is taken before the command goes out, so whatever the device does
                # after receiving it (on a replay: a recorded silence moving `clock` on) counts
                deadline = self._clock.now() + wait_s
                self._write(command)
                self.bytes_out += len(command)
                line = self._read_line(deadline)
                self.bytes_in += len(line)
            except serial.SerialTimeoutException:
                timeouts += 1
                continue
            except _PORT_GONE as exc:
                # the port went away (a USB adapter unplugged, the device restarted): open it
                # again by its name for the next attempt; a device back under that name answers
                gone = exc
                self._serial.close()
                timeouts += 1
                continue
            if not line:
                timeouts += 1
                continue
            try:
                fields = p.split_reply(line)
                p.raise_if_error(fields, shown, self.port)
                return parse(fields)
            except p.ProtocolError as exc:
                last_problem = (str(exc), line)
        attempts = self.retries + 1
        if gone is not None:
            raise DriverError(
                f"interferometer on {self.port}: the port failed on {attempts} attempts ({gone}).",
                hint="The port went away (cable unplugged, simulator stopped?); it was not back in time. Reconnect.",
            )
        if last_problem is None:
            raise CommTimeout(
                f"interferometer on {self.port} did not answer {shown!r} within {wait_s:g} s "
                f"({attempts} attempts, {wait_s * attempts:g} s in total)."
            )
        reason, line = last_problem
        raise FramingError(
            f"interferometer on {self.port}: malformed reply to {shown!r} after {attempts} attempts "
            f"({timeouts} without reply): {reason}; last line {p.show_line(line)}."
        )

    def _posix_fd(self) -> int | None:
        """The file descriptor of pyserial's POSIX port (open), else None."""
        port = self._serial
        return getattr(port, "fd", None) if type(port) is _POSIX_SERIAL else None

    def _write(self, data: bytes) -> None:
        """Write a command. On pyserial's POSIX port, one os.write when the line takes it whole
        (a command is a few bytes): pyserial's write then waits in select for the port to be
        writable again, with Timeout objects, on every call; what is left goes through it."""
        fd = self._posix_fd()
        if fd is not None:
            try:
                n = os.write(fd, data)
            except BlockingIOError:
                n = 0
            if n == len(data):
                return
            data = data[n:]
        self._serial.write(data)

    def _read_line(self, deadline: float) -> bytes:
        """Read one reply line until `deadline` (on the client's clock); b'' on silence, the
        partial line if the terminator did not come in time (the caller's split_reply rejects it).
        A port that fails raises (serial.SerialException, OSError): the caller reopens it.

        Not readline(): its timeout is per byte and a partial line looks complete. Not
        read_until() either: it reads byte by byte (0.35 ms per reply on a pty). Instead, wait
        for the first byte, then take what is waiting; the port's own timeout is a short poll
        slice so the deadline is kept within _POLL_S.
        """
        line = bytearray()
        port = self._serial
        fd = self._posix_fd()
        while True:
            if fd is not None:
                # pyserial's POSIX port, read as it does (select, then a non-blocking read) but
                # once per chunk: read(1) then read(in_waiting) costs two selects, an ioctl and
                # two Timeout objects per reply
                if select.select((fd,), (), (), port.timeout)[0]:
                    try:
                        chunk = os.read(fd, p.MAX_LINE_BYTES)
                    except BlockingIOError:
                        chunk = None  # raced away: as a silent poll slice
                    if chunk == b"":
                        raise serial.SerialException("device reports readiness to read but returned no data "
                                                     "(device disconnected or multiple access on port?)")
                    if chunk:
                        line += chunk
            else:
                waiting = port.in_waiting
                line += port.read(waiting if waiting else 1)
            end = line.find(p.TERMINATOR)
            if end >= 0:
                # bytes after the terminator are not an answer to anything: dropped
                return bytes(line[: end + len(p.TERMINATOR)])
            if len(line) >= p.MAX_LINE_BYTES or self._clock.now() >= deadline:
                return bytes(line)

    def _reopen(self, deadline: float) -> bool:
        """Open the port again by its name (same settings, exclusive) until `deadline` on the
        client's clock; True when it is open. For a port that went away and may come back."""
        while True:
            try:
                self._serial.open()
                self.reopened += 1
                return True
            except _PORT_GONE:
                if self._clock.now() >= deadline:
                    return False
                time.sleep(_POLL_S)

