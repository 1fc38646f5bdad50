"""Helpers shared by test modules (import as `from tests.tooling import ...`; the repo root is on
sys.path via pytest's `pythonpath`, and a plain `conftest` import is ambiguous across folders)."""

from __future__ import annotations

import os
import shutil

import pytest


def require_tool(name: str) -> str:
    """Path of a Debian tool; skip when absent, except on CI (CI=true) where it must exist."""
    path = shutil.which(name)
    if path:
        return path
    if os.environ.get("CI") == "true":
        pytest.fail(f"{name} is required on CI (.ci/run installs it)")
    pytest.skip(f"{name} not installed (apt-get install it to run this test)")


def start_drive_process(nv_path, legs: int = 1):
    """A simulated drive in its own process (so a test can SIGKILL it), keeping its table memory
    in `nv_path`. Returns (process, "tcp://127.0.0.1:PORT") once it listens."""
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    proc = subprocess.Popen(
        [sys.executable, "-m", "drivers.sim.drive_server", "--nv", str(nv_path), "--port", "0", "--legs", str(legs)],
        cwd=repo, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    line = proc.stdout.readline().strip()  # printed once it listens
    if not line.startswith("tcp://"):
        proc.kill()
        raise AssertionError(f"drive server did not start: {line!r} {proc.stderr.read()}")
    return proc, line


def kill_process(proc) -> None:
    """SIGKILL (no cleanup, like a power cut) and reap."""
    import signal

    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGKILL)
    proc.wait(10)


def write_points_session(path, points):
    """A completed session file at `path` holding `points` (POINT_DTYPE), written through the real
    SessionWriter. Returns the path."""
    from procedures.io.recording.writer import SessionWriter

    with SessionWriter.create(path, session_id=path.stem, operator="test", rig="sim", plan={"kind": "test"},
                              station_config={}, devices={}, software_version="test") as w:
        w.append_points(points)
        w.finish("completed")
    return path


def default_legs_points(legs=range(1, 7), cycles: int = 3, step_mm: float = 3.0, seed: int = 0):
    """Points of a small synthetic sweep straight from the simulated plant (procedures.synthetic, no
    protocol layer): `legs` of the default leg configs, uniform targets -90..90 mm."""
    import numpy as np

    from drivers.plant.leg import default_leg_configs
    from procedures.synthetic import synth_session

    cfgs = {leg: c for leg, c in zip(range(1, 7), default_leg_configs(seed=seed)) if leg in legs}
    return synth_session(cfgs, np.arange(-90.0, 90.01, step_mm), cycles=cycles, seed=seed)


async def start_paper_sweep(pilot, legs: str) -> None:
    """On the terminal UI's Sweep page: the paper plan (361 targets, dwell 1 s: minutes of rig
    time at time scale 0.02) on `legs`, started with the Start button."""
    from textual.widgets import Input

    pilot.app.screen.query_one("#plan").value = "paper"
    await pilot.pause()
    pilot.app.screen.query_one("#legs", Input).value = legs
    await pilot.pause()
    await pilot.click("#start")


def lab_config(folder) -> "Path":
    """A station TOML in `folder` for certificates: recordings in folder/runs, a [lab] with a customer."""
    from pathlib import Path

    p = Path(folder) / "station.toml"
    p.write_text(f'[station]\nrecordings_dir = "{Path(folder) / "runs"}"\n[lab]\nname = "Hexapod Metrology Lab"\n'
                 'address = "Werkstr. 5, Musterstadt"\naccreditation = "D-K-12345-01-00"\ncustomer = "ACME"\n')
    return p


def write_identified_session(path, points, *, station_id="bench-1", serial="HX-0042", leg_type="HX300",
                             plan=None, station_config=None, calibration_due="2099-01-01", started_utc=None,
                             rig="sim", devices=None, part_number="HX-L-300"):
    """A completed session file at `path` holding `points`, with an identity (station, the serial
    and leg type of every leg, a laser in calibration unless `calibration_due` = None) written
    through the real SessionWriter; `rig` as the runner records it ("sim", "live"), `devices` what
    the devices reported. Returns the path."""
    import numpy as np

    from procedures.io.recording.identity import InstrumentIdentity, LegIdentity, SessionIdentity, StationIdentity
    from procedures.io.recording.writer import SessionWriter

    legs = {int(leg): LegIdentity(serial=serial, part_number=part_number, leg_type=leg_type)
            for leg in np.unique(points["leg"])}
    ident = SessionIdentity(station=StationIdentity(id=station_id, host="host-" + station_id), operator="test",
                            software_version="test", legs=legs,
                            instrument=InstrumentIdentity("LI-6", "SIM-0001", calibration_due, "2026-01-10",
                                                          calibration_due is not None))
    with SessionWriter.create(path, session_id=path.stem, operator="test", rig=rig, plan=plan or {"kind": "test"},
                              station_config=station_config or {}, devices=devices or {}, software_version="test",
                              identity=ident.to_json(), started_utc=started_utc) as w:
        w.append_points(points)
        w.finish("completed")
    return path


class _ScaledFit:
    """A leg fit predicting `factor` times what `fit` predicts; everything else is `fit`'s."""

    def __init__(self, fit, factor: float) -> None:
        self._fit, self._factor = fit, float(factor)

    def __getattr__(self, name):
        return getattr(self._fit, name)

    def predict_um(self, position_mm, direction=1):
        return self._factor * self._fit.predict_um(position_mm, direction)


def slipped_model(model, peak_um: float = 180.0):
    """`model` (procedures.fit.LegErrorModel) as if its error had been read in the wrong unit: every
    leg's prediction scaled so its largest correction is `peak_um` (beyond 100 um, most likely nm,
    yet within the simulated drive's +/-300 um), while its recorded error span stays the real one."""
    import numpy as np

    from procedures.fit.model import LegErrorModel

    legs = {}
    for leg, fit in model.legs.items():
        x = np.linspace(fit.stroke_mm[0], fit.stroke_mm[1], 201)
        worst = max(float(np.max(np.abs(fit.predict_um(x, d)))) for d in (1, -1))
        legs[leg] = _ScaledFit(fit, peak_um / worst)
    return LegErrorModel(model.method, legs, model.source, model.options, model.created_utc, model.identity)


def imported_names(module: str) -> dict[str, str]:
    """Name -> "source.module.name" for every `from M import name [as alias]` anywhere in `module`
    (at the top or inside a function: the commands import what a run needs inside run(), so
    that `--help` loads nothing heavy). For asserting that a front end uses a shared object
    without importing the front end's heavy dependencies to compare identities."""
    import ast
    import importlib.util

    spec = importlib.util.find_spec(module)
    tree = ast.parse(open(spec.origin, encoding="utf-8").read())
    package = module if spec.origin.endswith("__init__.py") else module.rsplit(".", 1)[0]
    out: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                source = f"{base}.{node.module}" if node.module else base
            else:
                source = node.module or ""
            for alias in node.names:
                out[alias.asname or alias.name] = f"{source}.{alias.name}"
    return out


def defines(module: str, name: str) -> bool:
    """`module`'s source defines `name` itself (a def, class or assignment at its top level)."""
    import ast
    import importlib.util

    tree = ast.parse(open(importlib.util.find_spec(module).origin, encoding="utf-8").read())
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and node.name == name:
            return True
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets):
            return True
    return False


def onthefly_config(folder, protocol: str):
    """A station config on the simulated rig for on-the-fly tests: the laser `protocol` ("station"
    or "linef1"), recordings in `folder`, and the legs moving with a real drive's jerk limit (a
    pass's speed profile, not an instant step)."""
    from station.services.config import StationConfig

    cfg = StationConfig(operator="test")
    cfg.interferometer.protocol = protocol
    cfg.recordings_dir = str(folder)
    plain = cfg.sim.leg_configs
    cfg.sim.leg_configs = lambda: [c.with_leg_motion() for c in plain()]
    return cfg
