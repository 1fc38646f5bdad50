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
"""

from __future__ import annotations

import getpass
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

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


@dataclass
class StationConfig:
    operator: str = field(default_factory=lambda: _whoami())
    recordings_dir: str = "runs"
    drive: DriveConfig = field(default_factory=DriveConfig)
    interferometer: LaserConfig = field(default_factory=LaserConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    source: str = "built-in defaults"
    named: frozenset[str] = frozenset()  # "drive.url", "interferometer.port": the devices the file names

    @property
    def is_sim(self) -> bool:
        return self.drive.url == "sim" or self.interferometer.port == "sim"

    @property
    def audit_path(self) -> Path:
        """<recordings_dir>/audit.jsonl: the audit log both front ends use."""
        return Path(self.recordings_dir) / AUDIT_NAME

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
        return d

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


_SECTIONS = {"drive": DriveConfig, "interferometer": LaserConfig, "sim": SimConfig}

# (section, key) -> (lowest, strictly above it?, what the value is): physical sense of numbers
_RANGES = {
    ("drive", "timeout_s"): (0.0, True, "seconds to wait for a drive's reply"),
    ("interferometer", "timeout_s"): (0.0, True, "seconds to wait for the interferometer's reply"),
    ("interferometer", "baudrate"): (0, True, "the serial line's bits per second"),
    ("sim", "time_scale"): (0.0, False, "real seconds per simulated second"),
}


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
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p}: not valid TOML ({exc})") from None
    cfg.source = str(p)
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
                setattr(target, key, want(value))
            except (TypeError, ValueError):
                raise InputError(f"{p}: [{section}] {key}: expected a {want.__name__}, got {value!r}") from None
            if (section, key) in _RANGES:
                low, strict, what = _RANGES[section, key]
                v = getattr(target, key)
                if not (v > low if strict else v >= low) or v != v or v in (float("inf"), float("-inf")):
                    raise InputError(f"{p}: [{section}] {key} = {value!r}: must be a number {'>' if strict else '>='} "
                                     f"{low:g} ({what})")
            if (section, key) in (("drive", "url"), ("interferometer", "port")):
                cfg.named = cfg.named | {f"{section}.{key}"}
    unknown = set(data) - {"station", *_SECTIONS}
    if unknown:
        raise InputError(f"{p}: unknown section(s) {sorted(unknown)}")
    return cfg
