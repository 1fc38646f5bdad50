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
        return asdict(self)


def _whoami() -> str:
    try:
        return getpass.getuser()
    except Exception:
        return "unknown"


_SECTIONS = {"drive": DriveConfig, "interferometer": LaserConfig, "sim": SimConfig}


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
    unknown = set(data) - {"station", *_SECTIONS}
    if unknown:
        raise InputError(f"{p}: unknown section(s) {sorted(unknown)}")
    return cfg
