"""The real-hardware path: `station sim` runs the rig in its own process, and the station reaches
it only through a station TOML (`--config`), over Modbus TCP or RTU and a serial port, with the
system clock: exactly what it does with real drives and a real interferometer."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from procedures.io.recording.reader import read_session

REPO = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


@pytest.fixture(scope="module")
def sim_process():
    proc = subprocess.Popen([sys.executable, "-m", "station.cli", "sim", "--port", "0", "--rtu", "--time-scale", "0"],
                            cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    where: dict[str, str] = {}
    for line in proc.stdout:
        if m := re.search(r"drives \(Modbus TCP\): (tcp://127\.0\.0\.1:\d+)", line):
            where["tcp"] = m.group(1)
        if m := re.search(r"drives \(Modbus RTU\): (\S+)", line):
            where["rtu"] = m.group(1)
        if m := re.search(r"interferometer \(serial\): (\S+)", line):
            where["laser"] = m.group(1)
        if len(where) == 3:
            break
    assert len(where) == 3, f"station sim did not say where to reach it: {where}"
    yield where
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=20)


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_sweep_through_a_station_config_reaches_the_rig_in_another_process(sim_process, transport, tmp_path):
    url = sim_process["tcp"] if transport == "tcp" else f"rtu://{sim_process['rtu']}?baud=115200"
    cfg = tmp_path / "station.toml"
    cfg.write_text(f'[station]\noperator = "tester"\n[drive]\nurl = "{url}"\ntimeout_s = 2.0\n'
                   f'[interferometer]\nport = "{sim_process["laser"]}"\ntimeout_s = 1.0\n')
    out = tmp_path / f"{transport}.h5"
    r = subprocess.run([sys.executable, "-m", "station.cli", "sweep", "--config", str(cfg), "--legs", "2",
                        "--cycles", "1", "--n-targets", "5", "--dwell", "0", "--averaging", "0", "--out", str(out)],
                       cwd=REPO, env=ENV, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert f"rig: drives {url}, interferometer {sim_process['laser']}" in r.stdout
    s = read_session(out)
    assert s.outcome == "completed" and len(s.points) == 10
    assert s.attrs["rig"] == "live" and s.attrs["operator"] == "tester"
    assert s.devices["leg2"].startswith("StationSim LegServo-402")
    # the interferometer measured the leg the drive moved: errors of a few micrometres
    assert abs(s.points["error_um"]).max() < 10.0
    assert abs(s.points["drive_position_mm"] - s.points["target_mm"]).max() < 1e-3
