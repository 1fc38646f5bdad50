"""The replay drives: the simulated drive server (pymodbus, CiA 402, tables) in front of replay
plants instead of physical ones.

Everything the station's Modbus client sees is the simulated drive's behaviour (state machine,
moves, soft limits, tables), except three things taken from the recording when a move arrives
at the next recorded point: the axial load, the reported position actual, and a recorded drive
fault. Moves complete within the request (the device clock has time scale 0).
"""

from __future__ import annotations

import threading
from dataclasses import replace
from types import MappingProxyType

from drivers.modbus.profile import DriveProfile
from drivers.replay.clock import DeviceClock
from drivers.replay.plant import ReplayPlant
from drivers.sim.drive_server import SimDriveServer, DriveModel


class _ReplayDriveModel(DriveModel):
    """A simulated drive whose arrivals are checked against the recording."""

    plant: ReplayPlant

    def _arrive(self) -> None:
        super()._arrive()
        code = self.plant.arrived(self.cmd_mm, self.direction)
        if code is not None:
            self._fault(code)

    def _update_status(self) -> None:
        super()._update_status()
        if self.motion is None and self.plant.reported_position_mm is not None:
            self._set("position_actual", self.plant.reported_position_mm)


def replay_profile(profile: DriveProfile, tag: str) -> DriveProfile:
    """`profile` with the replay drive's identity: vendor StationReplay, serial R<tag>-<leg>."""
    ident = dict(profile.identity)
    ident.update(vendor="StationReplay", serial_prefix=f"R{tag[:8]}")
    return replace(profile, identity=MappingProxyType(ident))


class ReplayDriveServer(SimDriveServer):
    """Replay drives for `plants` (leg -> ReplayPlant; unit id = leg) on Modbus TCP/RTU.

    Start with `start_tcp()` / `start_rtu()`, end with `stop()` (as SimDriveServer). Tables are
    held in memory only: a replay never changes what the recording says.
    """

    def __init__(self, plants: dict[int, ReplayPlant], clock: DeviceClock, profile: DriveProfile,
                 lock: threading.RLock | None = None):
        super().__init__(plants, clock, profile, nv_path=None, lock=lock)
        self._models = {leg: _ReplayDriveModel(leg, plant, clock, profile) for leg, plant in sorted(plants.items())}
