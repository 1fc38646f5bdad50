"""Composition root: turn a StationConfig into connected drives and an interferometer.

Only this module (and tests) decide whether a leg is real, simulated or replayed. Even on the
simulated rig the station talks to the devices through the real protocol clients (Modbus TCP
on 127.0.0.1, serial over a pty), so nothing above the drivers can tell the difference.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from drivers.clock import SystemClock
from drivers.interfaces import Clock, Interferometer, ServoAxis, TableSpec
from drivers.interferometer.client import SerialInterferometer
from station.services.laser_wiring import open_laser, replay_laser, sim_rig_laser_options
from drivers.modbus.client import connect_axes
from drivers.modbus.profile import DriveProfile
from procedures.vocabulary import InputError
from station.services.config import StationConfig
from station.services.drive_lock import holds_drive_lock

if TYPE_CHECKING:  # annotations only: the simulated and replay rigs load when one is opened
    from drivers.replay import ReplayRig
    from drivers.sim.rig import SimRig


@dataclass
class Rig:
    axes: dict[int, ServoAxis]
    laser: Interferometer
    clock: Clock
    kind: str  # "sim" / "live" / "replay"
    description: str
    profile: DriveProfile | None = None
    sim: SimRig | ReplayRig | None = None  # the simulated (tests use it to inject faults) or replay rig
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


@holds_drive_lock(whole_rig=True)  # a leg another station process uses is refused (station/services/drive_lock.py)
def open_rig(cfg: StationConfig, legs=(1, 2, 3, 4, 5, 6), time_scale: float | None = None,
             noise_seed: int | None = None, leg_configs: list | None = None) -> Rig:
    """Connect to the rig named by `cfg`; on "sim" start the simulated rig in-process first.

    `noise_seed` (simulated rig only): seed of the measurement noise and pass offsets, so a
    later session (a verification) sees new noise on the same plant (`cfg.sim.seed`); None =
    the plant seed, which repeats a session's noise exactly. `leg_configs` (simulated rig only):
    the legs' plant configurations (drivers.plant.leg.PlantConfig, leg 1 first); None =
    `cfg.sim.leg_configs()` (the sample recordings bring their own legs)."""
    cfg.check_devices()  # a mixed config (one device simulated) is never opened, whichever front end asks
    profile = DriveProfile.load(cfg.drive.profile or None)
    if cfg.is_sim:
        from drivers.sim.rig import SimRig

        scale = cfg.sim.time_scale if time_scale is None else time_scale
        nv = Path(cfg.sim.nv_path) if cfg.sim.nv_path else None
        # the plant is always cfg.sim.seed's; only the noise follows noise_seed
        seed = cfg.sim.seed if noise_seed is None else int(noise_seed)
        configs = cfg.sim.leg_configs() if leg_configs is None else leg_configs
        sim = SimRig(time_scale=scale, seed=seed, configs=configs, nv_path=nv, profile=profile,
                     laser_offset_um=cfg.sim.laser_offset_um, **sim_rig_laser_options(cfg)).start()
        try:
            axes = _connect_legs(cfg, sim.drive_url, legs, profile, clock=sim.clock)
            laser = open_laser(cfg, sim.laser_port, sim.clock, sim=True)
        except Exception:
            sim.stop()
            raise
        desc = f"simulated rig (time scale {scale:g}): drives {sim.drive_url}, interferometer {sim.laser_port}"
        return Rig(axes, laser, sim.clock, "sim", desc, profile, sim, [sim.stop])
    axes = _connect_legs(cfg, cfg.drive.url, legs, profile)
    try:
        laser = open_laser(cfg, cfg.interferometer.port)
    except Exception:
        _close_axes(axes)
        raise
    desc = f"drives {cfg.drive.url}, interferometer {cfg.interferometer.port}"
    return Rig(axes, laser, SystemClock(), "live", desc, profile)


@dataclass
class DriveHandle:
    """Drives opened alone, without the interferometer (for a push or rollback): `axes` by leg,
    `url` (how they were reached, for the audit log), `close()` releases them (and the
    simulated drive). `axis` is the first leg's, for a single leg."""

    axes: dict[int, ServoAxis]
    url: str
    close: Callable[[], None]

    @property
    def axis(self) -> ServoAxis:
        return self.axes[min(self.axes)]

    def __enter__(self) -> "DriveHandle":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@holds_drive_lock(whole_rig=False)
def open_drive(cfg: StationConfig, legs: int | tuple[int, ...]) -> DriveHandle:
    """Connect to the drives of `legs` (one leg number or several) alone, never the
    interferometer: on the simulated rig (its table memory in cfg.sim.nv_path) or on the bus at
    cfg.drive.url, with cfg.drive.profile."""
    legs = (legs,) if isinstance(legs, int) else tuple(legs)
    profile = DriveProfile.load(cfg.drive.profile or None)

    if cfg.drive.url == "sim":
        from drivers.sim.rig import SimRig

        sim = SimRig(time_scale=0.0, seed=cfg.sim.seed, configs=cfg.sim.leg_configs(),
                     nv_path=Path(cfg.sim.nv_path) if cfg.sim.nv_path else None, profile=profile)
        port = sim.drive_server.start_tcp()
        try:
            axes = _connect_legs(cfg, f"tcp://127.0.0.1:{port}", legs, profile, clock=sim.clock)
        except BaseException:
            sim.drive_server.stop()
            raise

        def close() -> None:
            _close_axes(axes)
            sim.drive_server.stop()

        return DriveHandle(dict(axes), f"sim ({cfg.sim.nv_path})" if cfg.sim.nv_path else "sim", close)
    axes = _connect_legs(cfg, cfg.drive.url, legs, profile)
    return DriveHandle(dict(axes), cfg.drive.url, lambda: _close_axes(axes))


def _connect_legs(cfg: StationConfig, url: str, legs, profile: DriveProfile, **kwargs) -> dict[int, ServoAxis]:
    """The drives of `legs` at `url`, each wrapped as its [compensation] target needs
    (compensation_axes); nothing left open when that fails."""
    axes = connect_axes(url, legs, profile, timeout_s=cfg.drive.timeout_s, **kwargs)
    try:
        return compensation_axes(cfg, axes)
    except BaseException:
        _close_axes(axes)
        raise


def _close_axes(axes) -> None:
    for axis in axes.values():
        try:
            axis.close()
        except Exception:
            pass


def compensation_axes(cfg: StationConfig, axes: dict[int, ServoAxis]) -> dict[int, ServoAxis]:
    """`axes` with every leg whose [compensation] target is `station` wrapped in the station-side
    table (drivers/station_compensation.py, its store at cfg.station_tables_path). TableError
    (one line) when such a leg's drive applies a non-empty table of its own: both would correct.
    Legs with target `drive` or `controller` keep their drive as it is (a push to a drive without
    a table is refused by the push itself, offering the other two targets)."""
    from drivers.station_compensation import StationCompensatedAxis, StationTableStore

    out = dict(axes)
    for leg, axis in axes.items():
        if cfg.compensation.target_of(leg) == "station":
            wrapped = StationCompensatedAxis(axis, StationTableStore(cfg.station_tables_path))
            wrapped.check_drive_table()
            out[leg] = wrapped
    return out


def drive_url_of(cfg: StationConfig) -> str:
    """How the config reaches the drives, as the audit log records it ("sim (memory file)" or the URL)."""
    if cfg.drive.url == "sim":
        return f"sim ({cfg.sim.nv_path})" if cfg.sim.nv_path else "sim"
    return cfg.drive.url


def drive_table_spec(profile_path: str | Path | None = None) -> TableSpec | None:
    """What the drive of a profile (the built-in one without a path) holds, without connecting:
    for making and checking tables offline; None for a drive without a table. InputError naming
    the profile when it is bad."""
    from drivers.modbus.client import table_spec
    from drivers.modbus.profile import ProfileError

    try:
        profile = DriveProfile.load(str(profile_path) if profile_path else None)
        if getattr(profile, "table", None) is None:
            return None
        return table_spec(profile)
    except ProfileError as exc:
        raise InputError(str(exc)) from None


def drive_soft_limits(profile_path: str | Path | None = None) -> tuple[float, float]:
    """(min_mm, max_mm): the soft travel limits of the drive of a profile (the built-in one
    without a path), without connecting; what bounds the targets of an imported session."""
    soft = DriveProfile.load(str(profile_path) if profile_path else None).limits
    return soft.soft_min_mm, soft.soft_max_mm


def station_store_table_spec(where: str) -> TableSpec:
    """What the station's own table store holds (compensation target station); `where` names
    its setting in messages."""
    from drivers.station_compensation import station_table_spec

    return station_table_spec(where)


def start_sim_rig(cfg_sim, time_scale: float, tcp_port: int, rtu: bool, nv_path: Path | None,
                  laser_protocol: str = "station"):
    """The simulated rig served standalone (`station sim`): started SimRig with the station's
    simulated legs (`cfg_sim`, a SimConfig) and its laser speaking `laser_protocol` ("station" or
    "linef1"); the caller stops it. OSError when the port is taken."""
    from drivers.sim.rig import SimRig

    cfg = StationConfig()
    cfg.interferometer.protocol = laser_protocol
    rig = SimRig(time_scale=time_scale, seed=cfg_sim.seed, tcp_port=tcp_port, rtu=rtu, nv_path=nv_path,
                 configs=cfg_sim.leg_configs(), **sim_rig_laser_options(cfg))
    rig.start()
    return rig


def leg_table_spec(cfg: StationConfig, leg: int) -> TableSpec:
    """What holds leg `leg`'s table by its [compensation] target, without connecting: the
    station's store (target station) or the drive of cfg's profile (target drive). InputError
    for a leg whose target is controller, or drive on a drive without a table (naming the others)."""
    target = cfg.compensation.target_of(leg)
    if target == "station":
        return station_store_table_spec(cfg.station_tables_path)
    if target == "controller":
        raise InputError(f"leg {leg}: compensation target is controller ([compensation] in {cfg.source}): the "
                         "controller applies the table; export it with `station table --format linuxcnc`")
    spec = drive_table_spec(cfg.drive.profile or None)
    if spec is None:
        raise InputError(f"leg {leg}: the drive (profile {cfg.drive.profile or 'built-in'}) holds no compensation "
                         f"table; set its target to station ([compensation] legs = {{ {leg} = \"station\" }}: the "
                         "station applies the table to every command) or controller (`station table --format linuxcnc`)")
    return spec


REPLAY_LASER_TIMEOUT_S = 10.0
"""Reply timeout of the interferometer client on a replay. The replay instrument answers in well
under a millisecond, but on a loaded machine a reply can come late; a timeout firing there
would ask again, a question the recording does not hold, so the timeout is long. It is measured
on the replay's TimeoutClock, on which a recorded time-out (replayed as silence) ends at once."""

REPLAY_DRIVE_TIMEOUT_S = 10.0
"""Reply timeout of the Modbus client on a replay, without retries: a replay drive answers every
request (a recorded time-out is replayed at the interferometer), so a timeout could only be a
machine too busy to answer in time, and must not become a fault, nor a write applied twice."""


def open_replay_rig(path: str | Path, speed: float | None = None, cfg: StationConfig | None = None,
                    legs=None) -> Rig:
    """Replay devices answering from the session file `path`, reached through the normal Modbus
    and serial clients. `speed`: None = as fast as possible, 1 = real time, N = N times faster.
    `legs`: the drives to connect (default: the legs of the recorded plan). The Rig's `sim` is
    the drivers.replay.ReplayRig (its `mismatch`, `ended`, `on_end`). See docs/replay.md."""
    from drivers.replay import ReplayRig, ReplayScript
    from procedures.acquisition.plans import SweepPlan
    from procedures.io.recording.reader import read_session

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
    replay = ReplayRig(script, speed=speed, profile=profile)
    # COMP? answers the recorded air compensation, so the replayed session records the same; the
    # file's name, not its path: the instrument's line is length-limited and cut a long temp path
    replay.laser_server.set_recorded_compensation(session.devices.get("laser_air_compensation"), path.name)
    replay.start()
    try:
        # nothing recorded may depend on the wall clock: no timeout may fire on a request the
        # replay answers, however loaded the machine (drivers/replay/clock.py)
        axes = connect_axes(replay.drive_url, legs, profile, timeout_s=REPLAY_DRIVE_TIMEOUT_S, retries=0)
        laser = SerialInterferometer(replay.laser_port, timeout_s=REPLAY_LASER_TIMEOUT_S, clock=replay.timeout_clock)
        laser = replay_laser(laser, session.devices.get("laser_air_compensation"))  # a µLine-F1 session's record
    except Exception:
        replay.stop()
        raise
    pace = "as fast as possible" if speed is None else ("real time" if speed == 1 else f"{speed:g}x real time")
    desc = (f"replay of {path} ({script.value_points} points, outcome {session.outcome}) {pace}: "
            f"drives {replay.drive_url}, interferometer {replay.laser_port}")
    return Rig(axes, laser, replay.clock, "replay", desc, profile, replay, [replay.stop])
