"""Replay devices: a drive and an interferometer that answer from a recorded HDF5 session.

They are served over the real protocols (a pymodbus server for the drives, a pseudo-terminal
for the interferometer), reusing the simulated servers with a *replay plant* in place of the
physical model, so the station's own clients run unchanged. See docs/replay.md.

    script = ReplayScript.from_arrays(points, faults, source="run.h5", outcome="completed")
    with ReplayRig(script, speed=None) as rig:      # None = as fast as possible
        rig.drive_url, rig.laser_port, rig.clock    # connect the normal clients to these
        rig.timeout_clock                           # the interferometer client's timeout clock
"""

from drivers.replay.clock import ReplayClock, TimeoutClock
from drivers.replay.replay_errors import ReplayDataError, ReplayMismatch
from drivers.replay.rig import ReplayRig
from drivers.replay.script import ReplayFault, ReplayPoint, ReplayScript

__all__ = ["ReplayClock", "ReplayDataError", "ReplayMismatch", "ReplayRig", "ReplayFault", "ReplayPoint",
           "ReplayScript", "TimeoutClock"]
