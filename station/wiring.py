"""Composition root: turn a StationConfig into connected drives and an interferometer.

Only this module (and tests) decide whether a leg is real, simulated or replayed. Even on the
simulated rig the station talks to the devices through the real protocol clients (Modbus TCP
on 127.0.0.1, serial over a pty), so nothing above the drivers can tell the difference.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.clock import SystemClock
from drivers.interfaces import Clock, Interferometer, ServoAxis, TableSpec
from drivers.interferometer.client import SerialInterferometer
from drivers.modbus.client import connect_axes
from drivers.modbus.profile import DriveProfile
from procedures.errors import InputError
from station.config import StationConfig


@dataclass
class Rig:
    axes: dict[int, ServoAxis]
    laser: Interferometer
    clock: Clock
    kind: str  # "sim" / "live" / "replay"
    description: str
    profile: DriveProfile | None = None
    sim: Any = None  # the SimRig when simulated (tests use it to inject faults)
    _closers: list = field(default_factory=list)

    def close(self) -> None:
        for axis in self.axes.values():
            try:
                axis.close()
            except Exception:
                pass
        try:
            self.laser.close()
        except Exception:
            pass
        for closer in reversed(self._closers):
            closer()
        self._closers.clear()

    def __enter__(self) -> "Rig":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_rig(cfg: StationConfig, legs=(1, 2, 3, 4, 5, 6), time_scale: float | None = None,
             noise_seed: int | None = None) -> Rig:
    """Connect to the rig named by `cfg`; on "sim" start the simulated rig in-process first.

    `noise_seed` (simulated rig only): seed of the measurement noise and pass offsets, so a
    later session (a verification) sees new noise on the same plant (`cfg.sim.seed`); None =
    the plant seed, which repeats a session's noise exactly."""
    profile = DriveProfile.load(cfg.drive.profile or None)
    if cfg.is_sim:
        from drivers.sim.plant import default_leg_configs
        from drivers.sim.rig import SimRig

        scale = cfg.sim.time_scale if time_scale is None else time_scale
        nv = Path(cfg.sim.nv_path) if cfg.sim.nv_path else None
        if noise_seed is None:
            sim = SimRig(time_scale=scale, seed=cfg.sim.seed, nv_path=nv, profile=profile).start()
        else:
            sim = SimRig(time_scale=scale, seed=int(noise_seed), configs=default_leg_configs(cfg.sim.seed),
                         nv_path=nv, profile=profile).start()
        try:
            axes = connect_axes(sim.drive_url, legs, profile, timeout_s=cfg.drive.timeout_s, clock=sim.clock)
            laser = SerialInterferometer(sim.laser_port, timeout_s=cfg.interferometer.timeout_s)
        except Exception:
            sim.stop()
            raise
        desc = f"simulated rig (time scale {scale:g}): drives {sim.drive_url}, interferometer {sim.laser_port}"
        return Rig(axes, laser, sim.clock, "sim", desc, profile, sim, [sim.stop])
    axes = connect_axes(cfg.drive.url, legs, profile, timeout_s=cfg.drive.timeout_s)
    try:
        laser = SerialInterferometer(cfg.interferometer.port, baudrate=cfg.interferometer.baudrate,
                                     timeout_s=cfg.interferometer.timeout_s)
    except Exception:
        for a in axes.values():
            a.close()
        raise
    desc = f"drives {cfg.drive.url}, interferometer {cfg.interferometer.port}"
    return Rig(axes, laser, SystemClock(), "live", desc, profile)


@dataclass
class DriveHandle:
    """One leg's drive opened alone (for a push or rollback): `axis`, `url` (how it was reached,
    for the audit log), `close()` releases it (and the simulated drive)."""

    axis: ServoAxis
    url: str
    close: Any

    def __enter__(self) -> "DriveHandle":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_drive(cfg: StationConfig, leg: int) -> DriveHandle:
    """Connect to `leg`'s drive alone, never the interferometer: on the simulated rig (its table
    memory in cfg.sim.nv_path) or on the bus at cfg.drive.url, with cfg.drive.profile."""
    profile = DriveProfile.load(cfg.drive.profile or None)
    if cfg.drive.url == "sim":
        from drivers.sim.rig import SimRig

        sim = SimRig(time_scale=0.0, seed=cfg.sim.seed, nv_path=Path(cfg.sim.nv_path) if cfg.sim.nv_path else None,
                     profile=profile)
        port = sim.drive_server.start_tcp()
        try:
            axis = connect_axes(f"tcp://127.0.0.1:{port}", [leg], profile, timeout_s=cfg.drive.timeout_s,
                                clock=sim.clock)[leg]
        except BaseException:
            sim.drive_server.stop()
            raise

        def close() -> None:
            axis.close()
            sim.drive_server.stop()

        return DriveHandle(axis, f"sim ({cfg.sim.nv_path})" if cfg.sim.nv_path else "sim", close)
    axis = connect_axes(cfg.drive.url, [leg], profile, timeout_s=cfg.drive.timeout_s)[leg]
    return DriveHandle(axis, cfg.drive.url, axis.close)


def drive_url_of(cfg: StationConfig) -> str:
    """How the config reaches the drives, as the audit log records it ("sim (memory file)" or the URL)."""
    if cfg.drive.url == "sim":
        return f"sim ({cfg.sim.nv_path})" if cfg.sim.nv_path else "sim"
    return cfg.drive.url


def drive_table_spec(profile_path: str | Path | None = None) -> TableSpec:
    """What the drive of a profile (the built-in one without a path) holds, without connecting:
    for making and checking tables offline. InputError naming the profile when it is bad."""
    from drivers.modbus.client import table_spec
    from drivers.modbus.profile import ProfileError

    try:
        return table_spec(DriveProfile.load(str(profile_path) if profile_path else None))
    except ProfileError as exc:
        raise InputError(str(exc)) from None


REPLAY_LASER_TIMEOUT_S = 0.2
"""Reply timeout of the interferometer client on a replay (the replay answers in well under a
millisecond; a recorded time-out is replayed as silence, so a short timeout keeps it quick)."""


def open_replay_rig(path: str | Path, speed: float | None = None, cfg: StationConfig | None = None,
                    legs=None) -> Rig:
    """Replay devices answering from the session file `path`, reached through the normal Modbus
    and serial clients. `speed`: None = as fast as possible, 1 = real time, N = N times faster.
    `legs`: the drives to connect (default: the legs of the recorded plan). The Rig's `sim` is
    the drivers.replay.ReplayRig (its `mismatch`, `ended`, `on_end`). See docs/replay.md."""
    from drivers.replay import ReplayRig, ReplayScript
    from procedures.plans import SweepPlan
    from procedures.recording.reader import read_session

    cfg = cfg or StationConfig()
    session = read_session(path)
    try:
        plan_points = SweepPlan.from_dict(session.plan).points()
        directions = {pp.index: pp.direction for pp in plan_points}
        plan_legs = tuple(SweepPlan.from_dict(session.plan).legs)
    except (ValueError, TypeError):  # no usable plan (e.g. an import): fall back on run parity
        directions, plan_legs = {}, ()
    script = ReplayScript.from_arrays(
        session.points, session.faults, source=str(path), outcome=session.outcome, sha256=session.sha256,
        session_id=str(session.attrs.get("session_id", "")), directions=directions,
    )
    legs = tuple(legs or plan_legs or session.legs or (1,))
    # the recorded drive's register map, where it is at hand: its scaling (load, position) is
    # what the recorded values went through, so they come back through it bit for bit
    recorded = str((session.station_config.get("drive") or {}).get("profile") or "")
    profile = DriveProfile.load(recorded if recorded and Path(recorded).is_file() else (cfg.drive.profile or None))
    replay = ReplayRig(script, speed=speed, profile=profile).start()
    try:
        axes = connect_axes(replay.drive_url, legs, profile, timeout_s=cfg.drive.timeout_s)
        laser = SerialInterferometer(replay.laser_port, timeout_s=REPLAY_LASER_TIMEOUT_S)
    except Exception:
        replay.stop()
        raise
    pace = "as fast as possible" if speed is None else ("real time" if speed == 1 else f"{speed:g}x real time")
    desc = (f"replay of {path} ({script.value_points} points, outcome {session.outcome}) {pace}: "
            f"drives {replay.drive_url}, interferometer {replay.laser_port}")
    return Rig(axes, laser, replay.clock, "replay", desc, profile, replay, [replay.stop])
