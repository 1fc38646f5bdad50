"""Station configuration: which drives and interferometer to use, and how.

A TOML file selected with `--config`; without it the station runs on the simulated rig.

    [station]
    operator = "jdoe"
    recordings_dir = "runs"

    [drive]
    url = "sim"                 # or "tcp://127.0.0.1:5020", "rtu:///dev/ttyUSB0?baud=115200"
    profile = ""                # drive profile TOML; "" = the built-in default profile
    timeout_s = 1.0

    [interferometer]
    port = "sim"                # or "/dev/ttyUSB1"
    baudrate = 115200
    timeout_s = 0.5

    [sim]
    time_scale = 0.0            # real seconds per simulated second (0 = no waiting)
    seed = 0
    nv_path = ""                # file for the simulated drive's table memory ("" = none)
    jerk_mm_s3 = 2000.0         # the simulated drives' jerk limit (a real leg's; 0 = not limited)
    ambient_ramp_k_per_h = 0.0  # the simulated hall warming (docs/metrology.md)
    thermal_tau_s = 1800.0      # how fast the simulated legs follow it, s

    [compensation]              # where each leg's table is applied (docs/compensation.md)
    target = "drive"            # "drive" (its table banks), "station" (the station corrects commands), "controller"
    legs = {}                   # per-leg override, e.g. { 3 = "station" }
    tables_path = ""            # the station-side table store ("" = <recordings_dir>/station-tables.json)

    [metrology]                 # the measurement chain (docs/metrology.md); all optional
    reference_temp_c = 20.0     # lengths are normalised to this material temperature (ISO 1)
    wavelength_nm = 632.991     # the laser's VACUUM wavelength, 400..1700 nm
    co2_ppm = 450.0             # CO2 content for the refractive index when not measured
    dead_path_mm = 0.0          # laser to interferometer zero, beam path not counted by the laser
    laser_accuracy_ppm = 0.5    # instrument's stated accuracy, EXPANDED (k = 2)
    laser_resolution_nm = 1.0
    model = ""                  # instrument identification
    serial = ""
    calibration_date = ""       # ISO date of its last calibration, YYYY-MM-DD
    air_temp_u_c = 0.1          # STANDARD uncertainties (k = 1) of the sensors
    pressure_u_pa = 50.0
    humidity_u_pct = 3.0
    material_temp_u_c = 0.1
    misalignment_mm = 0.0       # lateral beam offset over the stroke (cosine error)
    abbe_offset_mm = 0.0
    abbe_angle_u_urad = 0.0

    [legs]                      # material of every leg (defaults: steel)
    expansion_um_m_k = 11.5     # linear expansion coefficient, um/m/K
    expansion_u_um_m_k = 1.0    # its standard uncertainty
    fixed_point_mm = 0.0        # target_mm where the leg is fixed (zero thermal expansion)
    [legs.3]                    # per-leg override, legs 1..6
    fixed_point_mm = -150.0
"""

from __future__ import annotations

import datetime as _dt
import getpass
import math
import tomllib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from drivers.sim.plant import LEG_JERK_MM_S3 as SIM_LEG_JERK_MM_S3
from procedures.errors import InputError


LEG_COUNT = 6
"""Legs of the platform this station calibrates (a Gough-Stewart hexapod): legs 1..6."""

AUDIT_NAME = "audit.jsonl"
"""The audit log's file name in the recordings folder (push, rollback, verify)."""

SIM_NV_NAME = "sim-drive-nv.json"
"""The simulated drive's table memory in the recordings folder (what `push --sim` wrote)."""


@dataclass
class DriveConfig:
    url: str = "sim"
    profile: str = ""
    timeout_s: float = 1.0


@dataclass
class LaserConfig:
    port: str = "sim"
    baudrate: int = 115200
    timeout_s: float = 0.5


@dataclass
class SimConfig:
    time_scale: float = 0.0
    seed: int = 0
    nv_path: str = ""
    ambient_ramp_k_per_h: float = 0.0  # the simulated hall warms by this (a leg warming during a sweep)
    thermal_tau_s: float = 1800.0  # how fast the simulated legs' material follows the hall
    # the simulated drives' jerk limit, mm/s^3 (0 = not limited): a real leg's by default, so the
    # rig time a user sees for any plan is a real leg's (drivers.sim.plant LEG_JERK_MM_S3); the
    # sample recordings pin 0, the setting they were made with (station/services/samples.py)
    jerk_mm_s3: float = SIM_LEG_JERK_MM_S3

    def leg_configs(self) -> list:
        """The simulated legs' plant configurations (drivers.sim.plant) for this seed, ramp, time
        constant and jerk limit."""
        from drivers.sim.plant import PlantConfig, default_leg_configs

        return default_leg_configs(self.seed, base=PlantConfig(ambient_ramp_k_per_h=self.ambient_ramp_k_per_h,
                                                               tau_s=self.thermal_tau_s,
                                                               jerk_mm_s3=float(self.jerk_mm_s3)))


@dataclass
class MetrologyConfig:
    """The measurement chain's settings (docs/metrology.md). Uncertainties named `*_u_*` are
    standard uncertainties (k = 1); `laser_accuracy_ppm` is the instrument's stated accuracy,
    an expanded uncertainty (k = 2), as laser makers state it."""

    reference_temp_c: float = 20.0  # ISO 1 reference temperature of lengths
    wavelength_nm: float = 632.991  # vacuum wavelength of the laser (HeNe)
    co2_ppm: float = 450.0  # CO2 mole fraction used when the session has no CO2 reading
    dead_path_mm: float = 0.0  # beam path between the laser and the interferometer's zero
    laser_accuracy_ppm: float = 0.5  # stated accuracy, k = 2
    laser_resolution_nm: float = 1.0  # display/count resolution
    model: str = ""  # instrument identification: maker and model
    serial: str = ""
    calibration_date: str = ""  # ISO date (YYYY-MM-DD) of the instrument's calibration; "" = not stated
    air_temp_u_c: float = 0.1  # standard uncertainty of the air temperature sensor
    pressure_u_pa: float = 50.0  # of the pressure sensor
    humidity_u_pct: float = 3.0  # of the humidity sensor, %RH
    material_temp_u_c: float = 0.1  # of the material temperature sensor
    misalignment_mm: float = 0.0  # lateral beam offset over the whole stroke (cosine error)
    abbe_offset_mm: float = 0.0  # distance between the beam and the leg's axis
    abbe_angle_u_urad: float = 0.0  # standard uncertainty of the pitch/yaw angle over the stroke

    @property
    def instrument_model(self) -> str:
        return self.model

    @property
    def instrument_serial(self) -> str:
        return self.serial


@dataclass(frozen=True)
class LegMaterial:
    """A leg's thermal expansion: `expansion_um_m_k` (um per metre per kelvin, steel 11.5) with
    its standard uncertainty `expansion_u_um_m_k`, and `fixed_point_mm`, the position in the
    station's target_mm coordinate where the leg is fixed, so that its thermal expansion is
    zero there (docs/metrology.md)."""

    expansion_um_m_k: float = 11.5
    expansion_u_um_m_k: float = 1.0
    fixed_point_mm: float = 0.0


COMPENSATION_TARGETS = ("drive", "station", "controller")
"""Where a leg's compensation table lives (docs/compensation.md): the drive's table banks, the
station (it subtracts the table from every target it commands), or a controller's files."""

STATION_TABLES_NAME = "station-tables.json"
"""The station-side table store's default file name in the recordings folder."""


@dataclass
class CompensationConfig:
    """[compensation]: `target` for every leg, `legs` overrides per leg ({3 = "station"}),
    `tables_path` the station-side table store ("" = <recordings_dir>/station-tables.json)."""

    target: str = "drive"
    legs: dict = field(default_factory=dict)
    tables_path: str = ""

    def target_of(self, leg: int) -> str:
        return self.legs.get(int(leg), self.target)

    def check(self, where: str) -> None:
        """InputError naming `where` and the key for an unknown target or leg; keys become ints."""
        if self.target not in COMPENSATION_TARGETS:
            raise InputError(f"{where}: [compensation] target = {self.target!r}: must be one of "
                             f"{', '.join(COMPENSATION_TARGETS)}")
        legs = {}
        for key, value in self.legs.items():
            try:
                leg = int(key)
            except (TypeError, ValueError):
                leg = 0
            if not 1 <= leg <= LEG_COUNT:
                raise InputError(f"{where}: [compensation] legs key {key!r}: not a leg number 1..{LEG_COUNT}")
            if value not in COMPENSATION_TARGETS:
                raise InputError(f"{where}: [compensation] legs.{key} = {value!r}: must be one of "
                                 f"{', '.join(COMPENSATION_TARGETS)}")
            legs[leg] = value
        self.legs = legs


@dataclass
class StationConfig:
    operator: str = field(default_factory=lambda: _whoami())
    recordings_dir: str = "runs"
    drive: DriveConfig = field(default_factory=DriveConfig)
    interferometer: LaserConfig = field(default_factory=LaserConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    metrology: MetrologyConfig = field(default_factory=MetrologyConfig)
    legs: LegMaterial = field(default_factory=LegMaterial)  # [legs]: the default of every leg
    leg_overrides: dict[int, LegMaterial] = field(default_factory=dict)  # [legs.N]
    legs_from_file: bool = False  # the file has a [legs] section
    compensation: CompensationConfig = field(default_factory=CompensationConfig)
    source: str = "built-in defaults"
    named: frozenset[str] = frozenset()  # "drive.url", "interferometer.port": the devices the file names

    @property
    def is_sim(self) -> bool:
        return self.drive.url == "sim" or self.interferometer.port == "sim"

    @property
    def audit_path(self) -> Path:
        """<recordings_dir>/audit.jsonl: the audit log both front ends use."""
        return Path(self.recordings_dir) / AUDIT_NAME

    @property
    def station_tables_path(self) -> Path:
        """The station-side table store: [compensation] tables_path, or <recordings_dir>/station-tables.json."""
        return Path(self.compensation.tables_path or Path(self.recordings_dir) / STATION_TABLES_NAME)

    def with_sim_memory(self) -> "StationConfig":
        """On the simulated drive, its table memory defaulted to <recordings_dir>/sim-drive-nv.json
        (so a push, a verification and a rollback see the same drive), its folder created."""
        if self.drive.url == "sim":
            if not self.sim.nv_path:
                self.sim.nv_path = str(Path(self.recordings_dir) / SIM_NV_NAME)
            Path(self.sim.nv_path).parent.mkdir(parents=True, exist_ok=True)
        return self

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("named")
        d["leg_overrides"] = {str(k): v for k, v in d["leg_overrides"].items()}  # JSON keys are strings
        # what the session's normalisation uses: every leg's effective material
        d["leg_materials"] = {str(n): asdict(self.material_of(n)) for n in range(1, LEG_COUNT + 1)}
        d["compensation"]["legs"] = {str(k): v for k, v in d["compensation"]["legs"].items()}
        return d

    def material_of(self, leg: int) -> LegMaterial:
        """Leg `leg`'s material: its `[legs.N]` override, else the `[legs]` default. On the
        simulated rig, when the file gives neither, the simulated leg's own material (its
        expansion coefficient, fixed at its bearing), so the normalisation and the twin agree."""
        leg = int(leg)
        if leg in self.leg_overrides:
            return self.leg_overrides[leg]
        if self.is_sim and not self.legs_from_file and 1 <= leg <= LEG_COUNT:
            plant = self.sim.leg_configs()[leg - 1]
            return replace(self.legs, expansion_um_m_k=plant.expansion_ppm_per_k, fixed_point_mm=plant.bearing_mm)
        return self.legs

    @property
    def from_file(self) -> bool:
        return self.source != "built-in defaults"

    def require_devices(self, *, drive: bool = True, interferometer: bool = True) -> None:
        """Refuse a config file that does not name the devices a live command drives: an empty
        or partial file would otherwise fall back on the simulated rig, and someone who meant
        the real drive would not be told. `url = "sim"` / `port = "sim"` name the simulator."""
        if not self.from_file:
            return
        missing = [f"[{key.split('.')[0]}] {key.split('.')[1]}" for key, wanted in
                   (("drive.url", drive), ("interferometer.port", interferometer)) if wanted and key not in self.named]
        if missing:
            raise InputError(f"{self.source}: names no {' and no '.join(missing)}: say which device to drive "
                             "(e.g. url = \"tcp://HOST:502\", port = \"/dev/ttyUSB1\"), or \"sim\" for the "
                             "simulated rig (or use --sim instead of --config)")

    def rig_text(self) -> str:
        """Which rig this config drives, for the first line a live command prints."""
        drive = "SIMULATED drives" if self.drive.url == "sim" else f"drives at {self.drive.url}"
        laser = "SIMULATED interferometer" if self.interferometer.port == "sim" else f"interferometer at {self.interferometer.port}"
        return f"{drive}, {laser} (config: {self.source})"


def _whoami() -> str:
    try:
        return getpass.getuser()
    except Exception:
        return "unknown"


_SECTIONS = {"drive": DriveConfig, "interferometer": LaserConfig, "sim": SimConfig,
             "compensation": CompensationConfig}

# (section, key) -> (lowest, strictly above it?, what the value is): physical sense of numbers
_RANGES = {
    ("drive", "timeout_s"): (0.0, True, "seconds to wait for a drive's reply"),
    ("interferometer", "timeout_s"): (0.0, True, "seconds to wait for the interferometer's reply"),
    ("interferometer", "baudrate"): (0, True, "the serial line's bits per second"),
    ("sim", "time_scale"): (0.0, False, "real seconds per simulated second"),
    ("sim", "thermal_tau_s"): (0.0, True, "seconds the simulated material takes to follow the hall"),
    ("sim", "jerk_mm_s3"): (0.0, False, "the simulated drives' jerk limit in mm/s^3, 0 = not limited; "
                                        f"a real leg's is {SIM_LEG_JERK_MM_S3:g}"),
}


# (section, key) -> (lowest, highest, what the value is): both bounds inclusive; the physical
# sense of the metrology numbers (a value outside is a typo or a unit mix-up, never a setting)
_BOUNDS = {
    ("metrology", "reference_temp_c"): (-10.0, 50.0, "the reference temperature of lengths, degC (ISO 1: 20)"),
    ("metrology", "wavelength_nm"): (400.0, 1700.0, "the laser's vacuum wavelength in nm (HeNe: 632.991); "
                                     "the refractive-index equations hold over 400..1700 nm"),
    ("metrology", "co2_ppm"): (0.0, 5000.0, "CO2 content of the air in ppm (about 450 outdoors)"),
    ("metrology", "dead_path_mm"): (0.0, 10000.0, "laser-to-zero beam path in mm"),
    ("metrology", "laser_accuracy_ppm"): (0.0, 100.0, "the laser's stated accuracy in ppm, k = 2"),
    ("metrology", "laser_resolution_nm"): (0.0, 10000.0, "the laser's resolution in nm"),
    ("metrology", "air_temp_u_c"): (0.0, 10.0, "standard uncertainty of the air temperature, K"),
    ("metrology", "pressure_u_pa"): (0.0, 10000.0, "standard uncertainty of the air pressure, Pa"),
    ("metrology", "humidity_u_pct"): (0.0, 100.0, "standard uncertainty of the relative humidity, %RH (0..100)"),
    ("metrology", "material_temp_u_c"): (0.0, 10.0, "standard uncertainty of the material temperature, K"),
    ("metrology", "misalignment_mm"): (0.0, 100.0, "lateral beam offset over the stroke, mm"),
    ("metrology", "abbe_offset_mm"): (0.0, 1000.0, "Abbe offset between beam and leg axis, mm"),
    ("metrology", "abbe_angle_u_urad"): (0.0, 10000.0, "standard uncertainty of the angular error, urad"),
    ("legs", "expansion_um_m_k"): (0.0, 50.0, "the linear expansion coefficient in um/m/K (steel 11.5, "
                                   "aluminium 23; none above 50)"),
    ("legs", "expansion_u_um_m_k"): (0.0, 50.0, "the standard uncertainty of the expansion coefficient, um/m/K"),
    ("legs", "fixed_point_mm"): (-5000.0, 5000.0, "target_mm where the leg is fixed, mm from mid-stroke"),
}


def _number(p: Path, where: str, key: str, value: Any, bounds: tuple[float, float, str] | None) -> float:
    """`value` as a finite float within `bounds`, else InputError naming file, section and key."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{p}: [{where}] {key}: expected a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"{p}: [{where}] {key} = {value!r}: must be a finite number")
    if bounds is not None:
        low, high, what = bounds
        if not low <= v <= high:
            raise InputError(f"{p}: [{where}] {key} = {value!r}: must be within {low:g}..{high:g} ({what})")
    return v


def _iso_date(p: Path, value: Any) -> str:
    text = str(value) if isinstance(value, _dt.date) else value  # TOML may give a date literal
    if not isinstance(text, str):
        raise InputError(f"{p}: [metrology] calibration_date: expected an ISO date YYYY-MM-DD, got {value!r}")
    if text == "":
        return ""
    try:
        _dt.date.fromisoformat(text)
        if len(text) != 10:
            raise ValueError
    except ValueError:
        raise InputError(f"{p}: [metrology] calibration_date = {value!r}: not an ISO date; write it as "
                         "YYYY-MM-DD, e.g. 2026-03-14") from None
    return text


def _load_metrology(p: Path, table: Any) -> MetrologyConfig:
    if not isinstance(table, dict):
        raise InputError(f"{p}: [metrology] must be a table of keys")
    m = MetrologyConfig()
    fields = MetrologyConfig.__dataclass_fields__
    for key, value in table.items():
        if key not in fields:
            raise InputError(f"{p}: [metrology] {key}: unknown key (known: {', '.join(fields)})")
        if key == "calibration_date":
            setattr(m, key, _iso_date(p, value))
        elif isinstance(getattr(m, key), str):
            if not isinstance(value, str):
                raise InputError(f"{p}: [metrology] {key}: expected text, got {value!r}")
            setattr(m, key, value)
        else:
            setattr(m, key, _number(p, "metrology", key, value, _BOUNDS.get(("metrology", key))))
    return m


def _material(p: Path, where: str, table: dict, base: LegMaterial) -> LegMaterial:
    fields = LegMaterial.__dataclass_fields__
    values = {}
    for key, value in table.items():
        if key not in fields:
            raise InputError(f"{p}: [{where}] {key}: unknown key (known: {', '.join(fields)}; per-leg "
                             "overrides go in [legs.1] .. [legs.6])")
        values[key] = _number(p, where, key, value, _BOUNDS[("legs", key)])
    return replace(base, **values)


def _load_legs(p: Path, table: Any) -> tuple[LegMaterial, dict[int, LegMaterial]]:
    if not isinstance(table, dict):
        raise InputError(f"{p}: [legs] must be a table of keys")
    own = {k: v for k, v in table.items() if not isinstance(v, dict)}
    default = _material(p, "legs", own, LegMaterial())
    overrides: dict[int, LegMaterial] = {}
    for key, sub in table.items():
        if not isinstance(sub, dict):
            continue
        if not (key.isdigit() and 1 <= int(key) <= LEG_COUNT):
            raise InputError(f"{p}: [legs.{key}]: not a leg; per-leg sections are [legs.1] .. [legs.{LEG_COUNT}]")
        overrides[int(key)] = _material(p, f"legs.{key}", sub, default)
    return default, overrides


def _convert(want: type, value: Any) -> Any:
    """`value` as a `want` (str, int, float, dict) without guessing: TypeError / ValueError for a
    value of another type (a bool or a fraction for an int, a number for a text...)."""
    if isinstance(value, bool) and want is not bool:
        raise TypeError(value)
    if want is str and not isinstance(value, str) or want is dict and not isinstance(value, dict):
        raise TypeError(value)
    if want is int and isinstance(value, float) and not value.is_integer():
        raise ValueError(value)
    return want(value)


def load_config(path: str | Path | None) -> StationConfig:
    """Read a station TOML; unknown keys and wrong types are refused with file and key named."""
    cfg = StationConfig()
    if path is None:
        return cfg
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except FileNotFoundError:
        raise InputError(f"{p}: config file not found") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{p}: not a UTF-8 text file (byte {exc.start}); a config is TOML text") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p}: not valid TOML ({exc})") from None
    cfg.source = str(p)
    for section in ("station", *_SECTIONS):
        if not isinstance(data.get(section, {}), dict):
            raise InputError(f"{p}: {section} must be a section ([{section}] and its keys), got {data[section]!r}")
    for key, value in data.get("station", {}).items():
        if key not in ("operator", "recordings_dir"):
            raise InputError(f"{p}: [station] {key}: unknown key (known: operator, recordings_dir)")
        setattr(cfg, key, str(value))
    for section, cls in _SECTIONS.items():
        target = getattr(cfg, section)
        for key, value in data.get(section, {}).items():
            if key not in cls.__dataclass_fields__:
                raise InputError(f"{p}: [{section}] {key}: unknown key (known: {', '.join(cls.__dataclass_fields__)})")
            want = type(getattr(target, key))
            try:
                setattr(target, key, _convert(want, value))
            except (TypeError, ValueError, OverflowError):
                raise InputError(f"{p}: [{section}] {key}: expected a {want.__name__}, got {value!r}") from None
            if (section, key) in _RANGES:
                low, strict, what = _RANGES[section, key]
                v = getattr(target, key)
                if not (v > low if strict else v >= low) or v != v or v in (float("inf"), float("-inf")):
                    raise InputError(f"{p}: [{section}] {key} = {value!r}: must be a number {'>' if strict else '>='} "
                                     f"{low:g} ({what})")
            if (section, key) in (("drive", "url"), ("interferometer", "port")):
                cfg.named = cfg.named | {f"{section}.{key}"}
    if "metrology" in data:
        cfg.metrology = _load_metrology(p, data["metrology"])
    if "legs" in data:
        cfg.legs, cfg.leg_overrides = _load_legs(p, data["legs"])
        cfg.legs_from_file = True
    cfg.compensation.check(str(p))
    unknown = set(data) - {"station", *_SECTIONS, "metrology", "legs"}
    if unknown:
        raise InputError(f"{p}: unknown section(s) {sorted(unknown)}")
    return cfg
