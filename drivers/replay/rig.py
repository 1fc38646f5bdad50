"""The replay rig: replay drives (Modbus) and a replay interferometer (pty) for one recording.

Like drivers.sim.rig.SimRig, but the plants answer from a `ReplayScript` and the clock is a
`ReplayClock` (recorded time, played at `speed`). Connect the station's normal clients to
`drive_url` and `laser_port` (the interferometer client measuring its reply timeouts on
`timeout_clock`), and give procedures `clock`.
"""

from __future__ import annotations

import threading
from typing import Callable

from drivers.modbus.profile import DriveProfile
from drivers.replay.clock import ReplayClock, TimeoutClock
from drivers.replay.drive_server import ReplayDriveServer, replay_profile
from drivers.replay.replay_errors import ReplayMismatch
from drivers.replay.interferometer_server import ReplayInterferometer
from drivers.replay.plant import ReplayPlant, ReplayState
from drivers.replay.script import ReplayScript
from drivers.sim.position_compare import TriggerLine

AXES = 6


class ReplayRig:
    """Replay devices for `script`. `speed`: None = as fast as possible, 1 = real time,
    N = N times faster. `rtu=True` also serves the drives as Modbus RTU on a pty (`rtu_port`).

    After a run: `mismatch` is the first request the recording could not answer (None if
    none), `ended` the reason the recording ran out ("" if it did not), `served` the number of
    recorded readings replayed. Set `on_end` to be called (with the reason) when a procedure
    asks for more than a cut-short recording holds; `station replay` aborts the run there, as
    the recorded run was.
    """

    def __init__(self, script: ReplayScript, speed: float | None = None, profile: DriveProfile | None = None,
                 rtu: bool = False):
        self.script = script
        self.clock = ReplayClock(speed)
        self.timeout_clock = TimeoutClock()
        base = profile or DriveProfile.load()
        tol_mm = base.registers["target_position"].scale or 1e-6
        self.state = ReplayState(script, self.clock, target_tol_mm=tol_mm)
        axes = max([AXES, *script.legs])
        self.plants = {leg: ReplayPlant(leg, self.state) for leg in range(1, axes + 1)}
        self.lock = threading.RLock()
        tag = script.sha256[:8] or "00000000"
        self.profile = replay_profile(base, tag)
        device_clock = self.clock.device_clock()
        self.drive_server = ReplayDriveServer(self.plants, device_clock, self.profile, lock=self.lock)
        identity = ("StationReplay", "LI-6", f"R{tag}", (script.session_id or "replay")[:24].replace(",", " ") or "replay")
        self.laser_server = ReplayInterferometer(self.state, self.plants, device_clock, self.lock, identity, axes=axes,
                                                 timeout_clock=self.timeout_clock)
        # on-the-fly sessions: the replay drives' position compare triggers the replay laser's capture
        self.trigger_line = TriggerLine()
        self.trigger_line.connect(self.laser_server.trigger)
        self.drive_server.connect_trigger(self.trigger_line)
        self.rtu = rtu
        self.drive_url = ""
        self.rtu_port = ""
        self.laser_port = ""
        self._started = False

    # -- results ------------------------------------------------------------------------------
    @property
    def mismatch(self) -> ReplayMismatch | None:
        return self.state.mismatch

    @property
    def ended(self) -> str:
        return self.state.ended

    @property
    def served(self) -> int:
        return self.state.served

    @property
    def on_end(self) -> Callable[[str], None] | None:
        return self.state.on_end

    @on_end.setter
    def on_end(self, fn: Callable[[str], None] | None) -> None:
        self.state.on_end = fn

    # -- life cycle ---------------------------------------------------------------------------
    def start(self) -> "ReplayRig":
        try:
            port = self.drive_server.start_tcp("127.0.0.1", 0)
            self.drive_url = f"tcp://127.0.0.1:{port}"
            if self.rtu:
                self.rtu_port = self.drive_server.start_rtu()
            self.laser_port = self.laser_server.start()
        except BaseException:
            self.drive_server.stop()
            raise
        self._started = True
        return self

    def stop(self) -> None:
        """Stop both servers. Idempotent."""
        if self._started:
            self._started = False
            try:
                self.laser_server.stop()
            finally:
                self.drive_server.stop()

    def __enter__(self) -> "ReplayRig":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
