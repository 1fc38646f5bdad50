"""Fuzzing the TOML readers: the station config (station/services/config.py load_config) and drive
profiles (drivers/modbus/profile.py DriveProfile.load).

Valid files (the documented config, the built-in profile) are damaged value by value, key by
key, and cut short; random TOML and random bytes too. Property: a config or profile that
holds sensible values, or the reader's own error (InputError / ProfileError, a DriverError)
naming the file; never another exception.
"""

from __future__ import annotations

import math
import tempfile
import tomllib
from pathlib import Path

from hypothesis import example, given, settings, strategies as st

from drivers.modbus.profile import DEFAULT_PROFILE, DriveProfile, ProfileError
from procedures.vocabulary import InputError
from station.services.config import load_config
from tests.fuzz import tomlgen
from tests.fuzz.tomlgen import damaged, toml_value
from tests.fuzz.budget import examples, fed

CONFIG = {
    "station": {"operator": "jdoe", "recordings_dir": "runs"},
    "drive": {"url": "tcp://127.0.0.1:5020", "profile": "", "timeout_s": 1.0},
    "interferometer": {"port": "/dev/ttyUSB1", "baudrate": 115200, "timeout_s": 0.5},
    "sim": {"time_scale": 0.0, "seed": 0, "nv_path": ""},
    "metrology": {"co2_ppm": 450.0, "calibration_date": "2026-03-14", "model": "XL-80"},
    "legs": {"expansion_um_m_k": 11.5, "3": {"fixed_point_mm": 10.0}},
    "compensation": {"target": "drive", "legs": {"3": "station"}},
}


def _write(d: str, name: str, data: bytes) -> Path:
    path = Path(d) / name
    path.write_bytes(data)
    return path


@settings(max_examples=examples(200))
@given(st.one_of(damaged(CONFIG), st.binary(max_size=120),
                 st.dictionaries(st.sampled_from(["station", "drive", "interferometer", "sim", "x"]),
                                 toml_value, max_size=4).map(lambda d: tomlgen.dumps(d).encode())))
@example(b"station = 5\n")  # found: a section that is not a table raised AttributeError
@example(b"[sim]\nseed = inf\n")  # found: OverflowError converting inf to an int
@example(b"[sim]\nseed = 1.5\n")  # was taken as seed 1
@example(b"[drive]\nurl = [1]\n")  # was taken as the text "[1]"
@example(b"\xff\xfe[drive]\n")  # found: not UTF-8 raised UnicodeDecodeError
def test_load_config_fuzzed(data):
    with tempfile.TemporaryDirectory() as d:
        path = _write(d, "station.toml", data)
        try:
            cfg = load_config(path)
        except InputError as exc:
            fed("station TOML (load_config)", refused=True)
            assert str(path) in str(exc), exc
            return
        fed("station TOML (load_config)")
        assert cfg.drive.timeout_s > 0 and math.isfinite(cfg.drive.timeout_s)
        assert cfg.interferometer.timeout_s > 0 and math.isfinite(cfg.interferometer.timeout_s)
        assert isinstance(cfg.interferometer.baudrate, int) and cfg.interferometer.baudrate > 0
        assert cfg.sim.time_scale >= 0 and math.isfinite(cfg.sim.time_scale)
        assert isinstance(cfg.sim.seed, int) and not isinstance(cfg.sim.seed, bool)
        for s in (cfg.operator, cfg.recordings_dir, cfg.drive.url, cfg.drive.profile, cfg.interferometer.port, cfg.sim.nv_path):
            assert isinstance(s, str)


PROFILE = tomllib.loads(DEFAULT_PROFILE.read_text())


@settings(max_examples=examples(200))
@given(st.one_of(damaged(PROFILE), damaged(PROFILE), st.binary(max_size=120)))
@example(tomlgen.dumps({**PROFILE, "table": {**PROFILE["table"], "max_correction_um": float("inf")}}).encode())
@example(tomlgen.dumps({**PROFILE, "limits": {**PROFILE["limits"], "soft_max_mm": float("inf")}}).encode())
@example(tomlgen.dumps({**PROFILE, "table": {**PROFILE["table"], "entry_scale_um": 5e-324}}).encode())
def test_drive_profile_fuzzed(data):
    with tempfile.TemporaryDirectory() as d:
        path = _write(d, "drive.toml", data)
        try:
            profile = DriveProfile.load(path)
        except ProfileError as exc:
            fed("drive profile TOML (DriveProfile.load)", refused=True)
            assert str(path) in str(exc), exc
            return
        fed("drive profile TOML (DriveProfile.load)")
        lim = profile.limits
        for v in (lim.soft_min_mm, lim.soft_max_mm, lim.max_velocity_mm_s, lim.max_accel_mm_s2, profile.table.max_correction_um):
            assert math.isfinite(v), lim
        assert lim.soft_min_mm < lim.soft_max_mm
        # what the client does with a loaded profile works: the soft limits encode into their registers
        # or are refused by the codec (its own error), and the table's header encodes
        for name, v in (("soft_limit_min", lim.soft_min_mm), ("soft_limit_max", lim.soft_max_mm)):
            try:
                profile.register(name).encode(v)
            except ValueError:  # CodecError: out of the register's range
                pass
        profile.table.encode_header({})


def test_seed_files_load():
    with tempfile.TemporaryDirectory() as d:
        assert load_config(_write(d, "c.toml", tomlgen.dumps(CONFIG).encode())).drive.url == "tcp://127.0.0.1:5020"
        assert DriveProfile.load(_write(d, "p.toml", tomlgen.dumps(PROFILE).encode())).name == "station-leg-drive"
