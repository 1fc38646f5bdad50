"""Station configuration: which drives and interferometer to use, and how.

A TOML file selected with `--config`; without it the station runs on the simulated rig.

    [station]
    operator = "jdoe"
    recordings_dir = "runs"
    id = "bench-2"              # the station's id in every session ("" = the host name)
    serials_file = ""           # CSV leg,serial[,part_number,leg_type,screw_lot] (station/services/serials.py)

    [drive]
    url = "sim"                 # or "tcp://127.0.0.1:5020", "rtu:///dev/ttyUSB0?baud=115200"
    profile = ""                # drive profile TOML; "" = the built-in default profile
    timeout_s = 1.0

    [interferometer]
    port = "sim"                # or "/dev/ttyUSB1"
    protocol = "station"        # or "linef1": a µLine-F1 / HPI-3D (docs/interferometer-protocol.md)
    baudrate = 115200           # linef1: 3000000 unless another rate is given
    timeout_s = 0.5

    [sim]
    time_scale = 0.0            # real seconds per simulated second (0 = no waiting)
    seed = 0
    nv_path = ""                # file for the simulated drive's table memory ("" = none)
    jerk_mm_s3 = 2000.0         # the simulated drives' jerk limit (a real leg's; 0 = not limited)
    ambient_ramp_k_per_h = 0.0  # the simulated hall warming (docs/metrology.md)
    thermal_tau_s = 1800.0      # how fast the simulated legs follow it, s
    laser_offset_um = 0.0       # added to every simulated laser reading after its zero: a station
                                # bias for comparison tests (docs/decisions.md); 0 = off

    [compensation]              # where each leg's table is applied (docs/compensation.md)
    target = "drive"            # "drive" (its table banks), "station" (the station corrects commands), "controller"
    legs = {}                   # per-leg override, e.g. { 3 = "station" }
    tables_path = ""            # the station-side table store ("" = <recordings_dir>/station-tables.json)

    [catalog]                   # the index of every record (docs/catalog.md); all optional
    url = ""                    # shared catalog, e.g. "postgresql://station@dbhost/catalog" ("" = local only)
    connect_timeout_s = 2.0     # how long a write waits for the shared catalog before keeping it in the backlog
    statement_timeout_s = 5.0   # the longest one shared-catalog statement (or its wait for a lock) may take
    calibration_interval_days = 365  # a leg is due this many days after its last calibration
    min_drift_interval_days = 30.0   # no drift figure from as-found calibrations closer together than this
    compare_window_days = 90.0  # stations are compared on sessions of one stage at most this many days apart
    [limits]                    # the largest sweep plan started without asking (procedures/acquisition/plan_size.py)
    max_points = 500000         # points measured, all legs
    max_rig_hours = 72.0        # estimated time on the rig

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
    calibration_due = ""        # ISO date its calibration expires; "" = not stated (not traceable)
    calibration_certificate = ""  # its certificate: number and issuing laboratory, e.g. "1234/2026, DAkkS D-K-15000-01-00"
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
    serial = "HX-0042"          # the leg's identity (recorded in every session; push checks it)
    part_number = "HX-L-300"
    leg_type = "HX300"
    screw_lot = "L2026-11"
    drive_serial = ""           # the drive's serial when the drive cannot say it

    [tolerances.HX300]          # upper limits (um) of a leg type, as found and as left (docs/decisions.md)
    E_um = 6.0                  # E, A, B, R, M: E_um, A_um, B_um, R_um, M_um
    [tolerances.HX300.as_left]  # limits after compensation (override per value)
    E_um = 3.0

    [lab]                       # the certificate's issuer and customer (docs/certificate.md)
    name = ""
    address = ""
    accreditation = ""          # e.g. "DAkkS D-K-12345-01-00"; "" = not accredited
    customer = ""               # default customer (station certificate --customer)
    customer_contact = ""       # the customer's contact: person, address or e-mail (--customer-contact)
    authoriser = ""             # who approves certificates (station certificate approve N --by NAME)
    authoriser_role = ""        # the authoriser's function, e.g. "Head of laboratory"
"""

from __future__ import annotations

import datetime as _dt
import math
import getpass
import tomllib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from drivers.plant.leg import LEG_JERK_MM_S3 as SIM_LEG_JERK_MM_S3
from procedures.reporting.decision import Tolerance, parse_tolerances
from procedures.vocabulary import InputError
from procedures.io.numbers import NotANumber, finite_float
from procedures.metrology import defaults as MD
from procedures.metrology.thermal import Material
from procedures.acquisition.plan_size import PlanLimits
from station import values as V  # one parser per kind of value, as on the command line (issue 31)


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


LASER_PROTOCOLS = ("station", "linef1")
"""The interferometer protocols a station speaks: its own (the default) and the µLine-F1 / HPI-3D's."""


@dataclass
class LaserConfig:
    port: str = "sim"
    baudrate: int = 115200
    timeout_s: float = 0.5
    protocol: str = "station"  # LASER_PROTOCOLS


@dataclass
class SimConfig:
    time_scale: float = 0.0
    seed: int = 0
    nv_path: str = ""
    ambient_ramp_k_per_h: float = 0.0  # the simulated hall warms by this (a leg warming during a sweep)
    thermal_tau_s: float = 1800.0  # how fast the simulated legs' material follows the hall
    # the simulated drives' jerk limit, mm/s^3 (0 = not limited): a real leg's by default, so the
    # rig time a user sees for any plan is a real leg's (drivers.plant.leg LEG_JERK_MM_S3); the
    # sample recordings pin 0, the setting they were made with (procedures.synthetic.SAMPLE_JERK_MM_S3)
    jerk_mm_s3: float = SIM_LEG_JERK_MM_S3
    # um added to every simulated laser reading after its zero (a station bias; 0 = off, so the
    # sample recordings stay identical): the station comparison's acceptance test (docs/decisions.md)
    laser_offset_um: float = 0.0

    def leg_configs(self) -> list:
        """The simulated legs' plant configurations (drivers.plant.leg) for this seed, ramp, time
        constant and jerk limit."""
        from drivers.plant.leg import PlantConfig, default_leg_configs

        return default_leg_configs(self.seed, base=PlantConfig(ambient_ramp_k_per_h=self.ambient_ramp_k_per_h,
                                                               tau_s=self.thermal_tau_s,
                                                               jerk_mm_s3=float(self.jerk_mm_s3)))


@dataclass
class MetrologyConfig:
    """The measurement chain's settings (docs/metrology.md). Uncertainties named `*_u_*` are
    standard uncertainties (k = 1); `laser_accuracy_ppm` is the instrument's stated accuracy,
    an expanded uncertainty (k = 2), as laser makers state it."""

    reference_temp_c: float = MD.REFERENCE_TEMP_C  # defaults and meanings: procedures.metrology.defaults
    wavelength_nm: float = MD.WAVELENGTH_NM
    co2_ppm: float = MD.CO2_PPM
    dead_path_mm: float = MD.DEAD_PATH_MM
    laser_accuracy_ppm: float = MD.LASER_ACCURACY_PPM
    laser_resolution_nm: float = MD.LASER_RESOLUTION_NM
    model: str = ""  # instrument identification: maker and model
    serial: str = ""
    calibration_date: str = ""  # ISO date (YYYY-MM-DD) of the instrument's calibration; "" = not stated
    calibration_due: str = ""  # ISO date its calibration expires; "" = not stated: results not traceable
    calibration_certificate: str = ""  # the instrument's own certificate: number and issuing laboratory (traceability)
    air_temp_u_c: float = MD.AIR_TEMP_U_C
    pressure_u_pa: float = MD.PRESSURE_U_PA
    humidity_u_pct: float = MD.HUMIDITY_U_PCT
    material_temp_u_c: float = MD.MATERIAL_TEMP_U_C
    misalignment_mm: float = MD.MISALIGNMENT_MM
    abbe_offset_mm: float = MD.ABBE_OFFSET_MM
    abbe_angle_u_urad: float = MD.ABBE_ANGLE_U_URAD


LegMaterial = Material
"""A leg's [legs] material: procedures.metrology.thermal.Material (one class, one set of defaults)."""


LEG_IDENTITY_KEYS = ("serial", "part_number", "leg_type", "screw_lot", "drive_serial")
"""[legs.N] keys naming the leg (and its drive), not its material: text, recorded in sessions."""


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
class CatalogConfig:
    """[catalog]: the shared catalog's `url` ("" = the local SQLite catalog only,
    <recordings_dir>/catalog.sqlite), the connect timeout and the calibration interval due
    dates are computed from (station/catalog, docs/catalog.md). The station's id is `[station] id`."""

    url: str = ""
    connect_timeout_s: float = 2.0
    # every statement on the shared catalog, and its wait for a lock another session holds, ends
    # after this (PostgreSQL statement_timeout and lock_timeout): then the record waits in the outbox
    statement_timeout_s: float = 5.0
    calibration_interval_days: int = 365
    # drift (um/month) between as-found calibrations closer than this is noise over a tiny span:
    # not computed (station/catalog/history.py)
    min_drift_interval_days: float = 30.0
    # the web's /compare pairs two stations' sessions of one leg only when measured this close: further
    # apart, their difference is the leg's drift or wear, not a station's bias
    compare_window_days: float = 90.0


@dataclass
class LabConfig:
    """[lab]: who issues certificates (docs/certificate.md); "" = not stated."""

    name: str = ""
    address: str = ""
    accreditation: str = ""
    customer: str = ""
    customer_contact: str = ""
    authoriser: str = ""  # the one person `station certificate approve --by` accepts
    authoriser_role: str = ""


@dataclass
class StationConfig:
    operator: str = field(default_factory=lambda: _whoami())
    recordings_dir: str = "runs"
    id: str = ""  # [station] id: the station's name in sessions; "" = the host name (station_id)
    serials_file: str = ""  # [station] serials_file: leg serials CSV read by every sweep
    drive: DriveConfig = field(default_factory=DriveConfig)
    interferometer: LaserConfig = field(default_factory=LaserConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    metrology: MetrologyConfig = field(default_factory=MetrologyConfig)
    legs: LegMaterial = field(default_factory=LegMaterial)  # [legs]: the default of every leg
    leg_overrides: dict[int, LegMaterial] = field(default_factory=dict)  # [legs.N]
    leg_identity: dict[int, dict[str, str]] = field(default_factory=dict)  # [legs.N] serial, part_number, ...
    legs_from_file: bool = False  # the file has a [legs] section
    compensation: CompensationConfig = field(default_factory=CompensationConfig)
    catalog: CatalogConfig = field(default_factory=CatalogConfig)
    limits: PlanLimits = field(default_factory=PlanLimits)  # [limits]: the largest plan started without asking
    lab: LabConfig = field(default_factory=LabConfig)
    tolerances: dict[str, Tolerance] = field(default_factory=dict)  # [tolerances.TYPE] (procedures.reporting.decision)
    web: dict[str, Any] = field(default_factory=dict)  # [web]: users, login, hosts; read by station/web/access.py
    source: str = "built-in defaults"
    named: frozenset[str] = frozenset()  # "drive.url", "interferometer.port": the devices the file names

    @property
    def is_sim(self) -> bool:
        """The simulated rig. Only meaningful for a config check_devices() accepts: a mixed one
        (one device simulated, the other real) is refused before anything connects."""
        return self.drive.url == "sim" or self.interferometer.port == "sim"

    def check_devices(self) -> None:
        """Refuse a config that mixes a simulated and a real device (`[drive] url = "tcp://..."`
        with `[interferometer] port = "sim"`, or the reverse): the station cannot drive a real leg
        and measure it with the simulator, and silently falling back on either would record,
        verify or push something else than the file names. Both keys are named."""
        drive_sim, laser_sim = self.drive.url == "sim", self.interferometer.port == "sim"
        if drive_sim != laser_sim:
            raise InputError(f"{self.source}: [drive] url = {self.drive.url!r} and [interferometer] port = "
                             f"{self.interferometer.port!r} mix a simulated and a real device; name both real "
                             "devices, or \"sim\" for both (the simulated rig); nothing was connected")

    @property
    def station_id(self) -> str:
        """[station] id, else the host name."""
        return self.id or _hostname()

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
        d["leg_identity"] = {str(k): v for k, v in d["leg_identity"].items()}
        # what the session's normalisation uses: every leg's effective material
        d["leg_materials"] = {str(n): asdict(self.material_of(n)) for n in range(1, LEG_COUNT + 1)}
        d["compensation"]["legs"] = {str(k): v for k, v in d["compensation"]["legs"].items()}
        d["tolerances"] = {k: t.to_json() for k, t in self.tolerances.items()}
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
        if interferometer or "interferometer.port" in self.named:  # a drive-only file (push) names no port
            self.check_devices()
        missing = [f"[{key.split('.')[0]}] {key.split('.')[1]}" for key, wanted in
                   (("drive.url", drive), ("interferometer.port", interferometer)) if wanted and key not in self.named]
        if missing:
            raise InputError(f"{self.source}: names no {' and no '.join(missing)}: say which device to drive "
                             "(e.g. url = \"tcp://HOST:502\", port = \"/dev/ttyUSB1\"), or \"sim\" for the "
                             "simulated rig (or use --sim instead of --config)")


def _hostname() -> str:
    import socket

    return socket.gethostname() or "unknown"


def _whoami() -> str:
    try:
        return getpass.getuser()
    except Exception:
        return "unknown"


_SECTIONS = {"drive": DriveConfig, "interferometer": LaserConfig, "sim": SimConfig,
             "compensation": CompensationConfig, "catalog": CatalogConfig, "limits": PlanLimits,
             "lab": LabConfig}

# (section, key) -> (lowest, strictly above it?, what the value is): physical sense of numbers
_RANGES = {
    ("drive", "timeout_s"): (0.0, True, "seconds to wait for a drive's reply"),
    ("interferometer", "timeout_s"): (0.0, True, "seconds to wait for the interferometer's reply"),
    ("interferometer", "baudrate"): (0, True, "the serial line's bits per second"),
    ("catalog", "connect_timeout_s"): (0.0, True, "seconds a write waits for the shared catalog"),
    ("catalog", "calibration_interval_days"): (0, True, "days from a leg's calibration to its next"),
    ("catalog", "statement_timeout_s"): (0.0, True, "seconds one statement on the shared catalog may take"),
    ("catalog", "min_drift_interval_days"): (0.0, False, "days between as-found calibrations below which no "
                                                         "drift is computed"),
    ("catalog", "compare_window_days"): (0.0, False, "days between two stations' sessions of a leg beyond which "
                                                     "the web does not compare them"),
    ("sim", "time_scale"): (0.0, False, "real seconds per simulated second"),
    ("limits", "max_points"): (0, True, "the most points a sweep plan may have"),
    ("limits", "max_rig_hours"): (0.0, True, "the longest a sweep plan may take on the rig, hours"),
    ("sim", "thermal_tau_s"): (0.0, True, "seconds the simulated material takes to follow the hall"),
    ("sim", "jerk_mm_s3"): (0.0, False, "the simulated drives' jerk limit in mm/s^3, 0 = not limited; "
                                        f"a real leg's is {SIM_LEG_JERK_MM_S3:g}"),
}


# (section, key) -> the kind of station/values.py its command-line option uses (`--seed`, `--time-scale`)
_KINDS = {
    ("sim", "seed"): V.SEED,
    ("sim", "time_scale"): V.TIME_SCALE,
}


# (section, key) -> (its kind in station/values.py, what the value is): the kind's bounds, both
# inclusive, are the physical sense of the metrology numbers (a value outside is a typo or a unit
# mix-up, never a setting), the same ones `station recorrect --co2-ppm` etc. apply (issue 31)
_BOUNDS = {
    ("metrology", "reference_temp_c"): (V.REFERENCE_TEMP_C, "the reference temperature of lengths, degC (ISO 1: 20)"),
    ("metrology", "wavelength_nm"): (V.WAVELENGTH_NM, "the laser's vacuum wavelength in nm (HeNe: 632.991); "
                                     "the refractive-index equations hold over 400..1700 nm"),
    ("metrology", "co2_ppm"): (V.CO2_PPM, "CO2 content of the air in ppm (about 450 outdoors)"),
    ("metrology", "dead_path_mm"): (V.DEAD_PATH_MM, "laser-to-zero beam path in mm"),
    ("metrology", "laser_accuracy_ppm"): (V.LASER_ACCURACY_PPM, "the laser's stated accuracy in ppm, k = 2"),
    ("metrology", "laser_resolution_nm"): (V.LASER_RESOLUTION_NM, "the laser's resolution in nm"),
    ("metrology", "air_temp_u_c"): (V.AIR_TEMP_U_C, "standard uncertainty of the air temperature, K"),
    ("metrology", "pressure_u_pa"): (V.PRESSURE_U_PA, "standard uncertainty of the air pressure, Pa"),
    ("metrology", "humidity_u_pct"): (V.HUMIDITY_U_PCT, "standard uncertainty of the relative humidity, %RH (0..100)"),
    ("metrology", "material_temp_u_c"): (V.MATERIAL_TEMP_U_C, "standard uncertainty of the material temperature, K"),
    ("metrology", "misalignment_mm"): (V.MISALIGNMENT_MM, "lateral beam offset over the stroke, mm"),
    ("metrology", "abbe_offset_mm"): (V.ABBE_OFFSET_MM, "Abbe offset between beam and leg axis, mm"),
    ("metrology", "abbe_angle_u_urad"): (V.ABBE_ANGLE_U_URAD, "standard uncertainty of the angular error, urad"),
    ("legs", "expansion_um_m_k"): (V.EXPANSION_UM_M_K, "the linear expansion coefficient in um/m/K (steel 11.5, "
                                   "aluminium 23; none above 50)"),
    ("legs", "expansion_u_um_m_k"): (V.EXPANSION_UM_M_K, "the standard uncertainty of the expansion coefficient, um/m/K"),
    ("legs", "fixed_point_mm"): (V.FIXED_POINT_MM, "target_mm where the leg is fixed, mm from mid-stroke"),
}


def _number(p: Path, where: str, key: str, value: Any, bounds: tuple[V.Kind, str] | None) -> float:
    """`value` as a finite float within `bounds`, else InputError naming file, section and key."""
    try:
        v = finite_float(value, text_ok=False)
    except NotANumber as exc:
        if exc.parsed is None:
            raise InputError(f"{p}: [{where}] {key}: expected a number, got {value!r}") from None
        raise InputError(f"{p}: [{where}] {key} = {value!r}: must be a finite number") from None
    if bounds is not None:
        kind, what = bounds
        low, high = kind.lo, kind.hi
        if not low <= v <= high:
            raise InputError(f"{p}: [{where}] {key} = {value!r}: must be within {low:g}..{high:g} ({what})")
    return v


def _iso_date(p: Path, value: Any, key: str = "calibration_date") -> str:
    text = str(value) if isinstance(value, _dt.date) else value  # TOML may give a date literal
    if not isinstance(text, str):
        raise InputError(f"{p}: [metrology] {key}: expected an ISO date YYYY-MM-DD, got {value!r}")
    if text == "":
        return ""
    try:
        V.DATE.parse(text)  # the one date rule, as `station legs --since` reads it
    except InputError:
        raise InputError(f"{p}: [metrology] {key} = {value!r}: not an ISO date; write it as "
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
        if key in ("calibration_date", "calibration_due"):
            setattr(m, key, _iso_date(p, value, key))
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
            raise InputError(f"{p}: [{where}] {key}: unknown key (known: {', '.join(fields)}; in [legs.N] also "
                             f"{', '.join(LEG_IDENTITY_KEYS)}; per-leg "
                             "overrides go in [legs.1] .. [legs.6])")
        values[key] = _number(p, where, key, value, _BOUNDS[("legs", key)])
    return replace(base, **values)


def _load_legs(p: Path, table: Any) -> tuple[LegMaterial, dict[int, LegMaterial], dict[int, dict[str, str]]]:
    if not isinstance(table, dict):
        raise InputError(f"{p}: [legs] must be a table of keys")
    own = {k: v for k, v in table.items() if not isinstance(v, dict)}
    default = _material(p, "legs", own, LegMaterial())
    overrides: dict[int, LegMaterial] = {}
    identity: dict[int, dict[str, str]] = {}
    for key, sub in table.items():
        if not isinstance(sub, dict):
            continue
        if not (key.isdigit() and 1 <= int(key) <= LEG_COUNT):
            raise InputError(f"{p}: [legs.{key}]: not a leg; per-leg sections are [legs.1] .. [legs.{LEG_COUNT}]")
        names = {k: v for k, v in sub.items() if k in LEG_IDENTITY_KEYS}
        for k, v in names.items():
            if not isinstance(v, str):
                raise InputError(f"{p}: [legs.{key}] {k}: expected text (e.g. \"HX-0042\"), got {v!r}")
        if names:
            from station.services.serials import check_serial  # one rule for serials everywhere

            for k in ("serial", "drive_serial"):
                if names.get(k):
                    check_serial(names[k], f"{p}: [legs.{key}] {k}")
            identity[int(key)] = {k: v for k, v in names.items() if v}
        material = {k: v for k, v in sub.items() if k not in LEG_IDENTITY_KEYS}
        if material:
            overrides[int(key)] = _material(p, f"legs.{key}", material, default)
    return default, overrides, identity


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


def tolerances_of_config(path: str | Path | None) -> dict[str, Tolerance]:
    """{leg type: Tolerance} of the station TOML at `path` (both stages), for the fleet's ISO
    14253-1 decisions; {} without a config (the web decides against these)."""
    return dict(load_config(path).tolerances) if path else {}


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
        if key not in ("operator", "recordings_dir", "id", "serials_file"):
            raise InputError(f"{p}: [station] {key}: unknown key (known: operator, recordings_dir, id, serials_file)")
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
            if (section, key) in _KINDS:  # the same kind as the command-line option of that value
                _KINDS[section, key].parse(getattr(target, key), f"{p}: [{section}] {key}")
            if (section, key) in (("drive", "url"), ("interferometer", "port")):
                cfg.named = cfg.named | {f"{section}.{key}"}
    if "metrology" in data:
        cfg.metrology = _load_metrology(p, data["metrology"])
    if "legs" in data:
        cfg.legs, cfg.leg_overrides, cfg.leg_identity = _load_legs(p, data["legs"])
        cfg.legs_from_file = True
    cfg.compensation.check(str(p))
    if cfg.interferometer.protocol not in LASER_PROTOCOLS:
        raise InputError(f"{p}: [interferometer] protocol = {cfg.interferometer.protocol!r}: must be one of "
                         f"{', '.join(repr(x) for x in LASER_PROTOCOLS)}")
    if not math.isfinite(cfg.sim.laser_offset_um):
        raise InputError(f"{p}: [sim] laser_offset_um = {cfg.sim.laser_offset_um!r}: must be a finite number of um")
    if "tolerances" in data:
        cfg.tolerances = parse_tolerances(data["tolerances"], str(p))
    if "web" in data:  # its keys are the web view's (station/web/access.parse_web_section checks them)
        if not isinstance(data["web"], dict):
            raise InputError(f"{p}: web must be a section ([web] and its keys), got {data['web']!r}")
        cfg.web = data["web"]
    unknown = set(data) - {"station", *_SECTIONS, "metrology", "legs", "tolerances", "web"}
    if unknown:
        raise InputError(f"{p}: unknown section(s) {sorted(unknown)}")
    return cfg
