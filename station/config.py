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
