"""The replay interferometer: the simulated instrument's pty server answering from the recording.

Position and environment replies carry the recorded values *exactly*: numbers are written with
`repr` (the shortest text that parses back to the same double) instead of the protocol's fixed
decimals (9 for positions, 1-3 for the environment), which would round values that did not come
through this protocol (an import, another instrument) and so change `error_um`. The client
parses both forms (`float()`), so nothing changes on its side. Other commands (identity,
averaging, zero) behave as on the simulated instrument.

`COMP?` answers the recording's own air-compensation record (`laser_air_compensation` in the
session's devices, `set_recorded_compensation`), its numbers exact, so a replayed session records
what the recorded one did; a recording whose instrument did not report one is answered with ERR 11
(the recorded refusal, replayed), a recording made before the record existed, or one whose record
cannot be sent, with ERR 10 naming why: never the simulator's default (docs/replay.md).
"""

from __future__ import annotations

import json
import math
import threading

from drivers.interferometer import protocol as p
from drivers.replay.clock import DeviceClock, TimeoutClock
from drivers.replay.plant import ReplayPlant, ReplayState
from drivers.replay.script import UNKNOWN_SIGNAL_PCT, ReplayPoint
from drivers.sim.interferometer_server import SimInterferometer
from drivers.states import FaultKind

ERR_NOT_RECORDED = 10
"""ERR code of a query the recording cannot answer (a mismatch, or the end of the recording)."""
ERR_REPLAYED = 11
"""ERR code of a recorded instrument error, replayed."""
_MAX_ERR_TEXT = 180  # an ERR line must stay well under the protocol's 256-byte line limit


def exact(value: float) -> str:
    """A float as the shortest text that parses back to the same double ('NAN' if NaN)."""
    return "NAN" if math.isnan(value) else repr(float(value))


def signal_text(pt: ReplayPoint) -> str:
    """A point's recorded signal level, exactly; an unknown one (a streamed pass's reading: the
    protocol needs 0..100 there) as UNKNOWN_SIGNAL_PCT, which the replay's recorder puts back."""
    return exact(UNKNOWN_SIGNAL_PCT if math.isnan(pt.signal_pct) else pt.signal_pct)


class ReplayInterferometer(SimInterferometer):
    """Serves the replay plants on a pty (`start()` returns the path for the client)."""

    def __init__(self, state: ReplayState, plants: dict[int, ReplayPlant], clock: DeviceClock,
                 lock: threading.RLock, identity: tuple[str, str, str, str], axes: int = 6,
                 timeout_clock: TimeoutClock | None = None):
        super().__init__(plants, clock, lock=lock, axes=axes, identity=identity)
        self.state = state
        self.timeout_clock = timeout_clock
        self._comp_reply = recorded_compensation_reply(None)  # until the recording's record is given

    def _position(self, axis: int) -> bytes | None:
        # No averaging window on the replay clock: a fresh answer (a reading, a fault) sets the
        # clock to its recorded time, and a query answered again (the same reading, the client's
        # retries into a replayed silence or line noise) must not move it, or the time the sweep
        # records after it would depend on how often the client asked.
        with self.lock:
            plant = self.plants.get(axis)
            if plant is None:
                return p.format_error(ERR_NOT_RECORDED, f"replay: axis {axis} has no leg in the recording")
            answer = plant.reading()
            t_s = self.clock.now()
            last = self._last_position_mm[axis]
            if answer.kind == "value":
                self._last_position_mm[axis] = answer.point.measured_mm
        kind = answer.kind
        if kind == "value":
            pt = answer.point
            return p.frame_reply("POS", axis, exact(pt.measured_mm), "OK", signal_text(pt), f"{t_s:.6f}")
        if kind == "beam":
            return p.frame_reply("POS", axis, exact(last), "BEAM", "0.0", f"{t_s:.6f}")
        if kind == "silent":
            if self.timeout_clock is not None:
                self.timeout_clock.silence()  # the client's wait for this reply ends now
            return None
        if kind == "garbage":
            good = p.frame_reply("POS", axis, exact(last), "OK", "90.0", f"{t_s:.6f}")
            return self._corrupt(good, "checksum")
        if kind == "end" and self.state.on_end is not None:
            # outside the rig lock: the callback may stop the drives over Modbus
            self.state.on_end(answer.text)
        code = ERR_REPLAYED if kind == "error" else ERR_NOT_RECORDED
        return p.format_error(code, answer.text[:_MAX_ERR_TEXT])

    def trigger(self, leg: int, t_s: float) -> None:
        """As the simulated instrument's, but a pulse of a failing attempt replayed as an error, a
        time-out or line noise latches nothing (`_capture_sample` None)."""
        cap = self._capture.get(leg)
        if cap is None or len(cap[1]) >= cap[0]:
            return
        sample = self._capture_sample(leg, t_s)
        if sample is not None:
            cap[1].append(sample)

    def _capture_sample(self, axis: int, t_s: float) -> tuple[str, str, str, str] | None:
        """A trigger pulse of an on-the-fly pass (the replay drive's position compare): latch the
        next recorded point of the leg, if it is the one at this compare position, with its
        recorded reading and time, exactly; a recorded beam break of the pass a BEAM sample, another
        recorded fault of the laser nothing (drivers.replay.plant.ReplayPlant.capture); a pulse the recording
        does not hold latches a BEAM sample and the mismatch is kept (docs/replay.md)."""
        plant = self.plants.get(axis)
        pt = plant.capture() if plant is not None else None
        if pt in (FaultKind.ERROR, FaultKind.TIMEOUT, FaultKind.FRAMING):
            return None
        if not isinstance(pt, ReplayPoint):
            return exact(self._last_position_mm[axis]), "BEAM", "0.0", f"{t_s:.6f}"
        self._last_position_mm[axis] = pt.measured_mm
        return exact(pt.measured_mm), "OK", signal_text(pt), exact(pt.time_s)

    def _capture_command(self, word: str, args: list[str]) -> bytes | None:
        axis = self._axis(args[:1])
        if isinstance(axis, bytes):
            return super()._capture_command(word, args)
        with self.lock:
            plant = self.plants.get(axis)
            mode = ended = None
            if plant is not None and word == p.CMD_CAP_ARM:
                plant.capture_armed()
            elif plant is not None:  # a replayed fault of a pass fails its attempt here, at its time
                mode = plant.capture_asked(count=word == p.CMD_CAP_COUNT)
            if word == p.CMD_CAP_COUNT:
                ended = self.state.ended
        if ended:  # a cut-short recording ended in this pass: end the run here, as recorded
            if self.state.on_end is not None:
                self.state.on_end(ended)  # outside the rig lock (see `_position`)
            return p.format_error(ERR_NOT_RECORDED, ended[:_MAX_ERR_TEXT])
        if mode == "silent":
            if self.timeout_clock is not None:
                self.timeout_clock.silence()  # the client's wait for this reply ends now
            return None
        reply = super()._capture_command(word, args)
        return self._corrupt(reply, "checksum") if mode == "garbage" else reply

    def _environment(self) -> bytes:
        with self.lock:
            air_c, pressure_hpa, humidity_pct, temps = self.state.environment(self.plants, self.axes)
        return p.frame_reply("ENV", exact(air_c), exact(pressure_hpa), exact(humidity_pct), *(exact(t) for t in temps))

    # -- COMP?: the recorded air-compensation record -------------------------------------------------
    def set_recorded_compensation(self, record: str | None, source: str = "the recording") -> None:
        """What COMP? answers from now on: the session's `laser_air_compensation` (None: the
        recording has none). See recorded_compensation_reply."""
        self._comp_reply = recorded_compensation_reply(record, source)

    def _handle(self, line: bytes) -> bytes | None:
        word, args = p.parse_command(line)
        if word == p.CMD_COMP and not args:
            self.commands[word] += 1
            return self._comp_reply
        return super()._handle(line)


def _err_text(text: str) -> str:
    return text[:_MAX_ERR_TEXT]


def recorded_compensation_reply(record: str | None, source: str = "the recording") -> bytes:
    """The reply to COMP? of a replay of a session whose `laser_air_compensation` is `record`.

    - the JSON record procedures.acquisition.sweep wrote from the recorded instrument's COMP? answer: that
      answer again, numbers exact (`repr`), so the replayed session's record is the same text;
    - "not reported (...)" (the recorded instrument refused COMP?, or its driver had none): ERR 11,
      the refusal replayed, the recorded text in it; the replayed session records it as not reported;
    - None or "" (a recording made before the record existed): ERR 10, saying the recording holds
      none; never the simulator's default, which would make a record the recording does not hold;
    - anything else (a record that is not valid JSON or not a valid COMP answer): ERR 10 naming why.
    """
    if not record:
        return p.format_error(ERR_NOT_RECORDED, _err_text(
            "replay: no air-compensation record (laser_air_compensation; recorded before the station asked "
            f"COMP?) in {source}"))  # the reason first: a long name is what the length limit cuts
    if record.startswith("not reported"):
        return p.format_error(ERR_REPLAYED, _err_text(f"replay: recorded as {record}"))
    try:
        doc = json.loads(record)
        fields = ["COMP", str(doc["mode"]), str(doc["equation"])]
        for key in ("wavelength_nm", "air_temp_c", "air_pressure_hpa", "humidity_pct", "co2_ppm", "dead_path_mm"):
            value = doc[key]
            fields.append("NAN" if value is None else exact(float(value)))
        p.parse_compensation(fields)  # what the client will check: refuse it here, with the reason
    except (ValueError, TypeError, KeyError, p.ProtocolError) as exc:
        why = f"missing key {exc.args[0]}" if isinstance(exc, KeyError) else str(exc)
        return p.format_error(ERR_NOT_RECORDED, _err_text(
            f"replay: the air-compensation record cannot be replayed ({why}) from {source}"))
    return p.frame_reply(*fields)
