"""`station X --help`, an argument error and a refusal load nothing heavy (issue 32, deliverable 6):
the command modules import what a run needs inside run(); and a sweep's first point waits for
no catalog (its sink opens the catalog after that point) though the session is still indexed
before the command ends. Checked on the modules a fresh process has loaded, not on time
(bench/bench_startup.py prints the times)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading

import pytest

from station.cli import _command_specs

HEAVY = ("sqlalchemy", "alembic", "mako", "h5py", "scipy", "textual", "matplotlib", "pymodbus", "serial",
         "fastapi", "starlette", "uvicorn", "jinja2")
"""The database, the recorder, the analyses, the UIs and the device links: seconds of CPU between them."""

RUNNER = """
import contextlib, io, json, sys
from station.cli import main
codes = []
for argv in json.loads(sys.argv[1]):
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            codes.append(main(argv))
        except SystemExit as exc:
            codes.append(exc.code)
print(json.dumps({"codes": codes, "loaded": sorted({m.split('.')[0] for m in sys.modules})}))
"""


def loaded_by(*argvs: list[str], cwd=None) -> tuple[list, set[str]]:
    """Exit codes of `station ARGV...` run one after the other in one fresh process, and the
    top-level packages loaded by the end."""
    out = subprocess.run([sys.executable, "-c", RUNNER, json.dumps(list(argvs))], capture_output=True, text=True,
                         cwd=cwd, timeout=120, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    return result["codes"], set(result["loaded"])


@pytest.mark.parametrize("command", sorted(_command_specs()))
def test_help_and_an_argument_error_load_nothing_heavy(command):
    codes, loaded = loaded_by([command, "--help"], [command, "--no-such-option"])
    assert codes == [0, 2]  # help printed; the bad option refused by argparse
    assert not loaded & set(HEAVY), f"station {command} --help / an argument error loaded {sorted(loaded & set(HEAVY))}"


def test_a_refused_sweep_loads_nothing_heavy(tmp_path):
    codes, loaded = loaded_by(["sweep", "--sim"], ["sweep", "--sim", "--resume", "missing.h5"],
                              ["sweep", "--sim", "--time-scale", "-1", "--out", "s.h5"], cwd=tmp_path)
    assert codes == [2, 2, 2]  # no --out; no such session; a negative time scale
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))
    assert not list(tmp_path.iterdir())


def test_the_check_sees_a_heavy_module():
    # guard against a check that passes because the runner loads nothing: a run's modules do show
    _, loaded = loaded_by(["iso230", "--help"], ["--version"])
    assert "station" in loaded and "h5py" not in loaded
    out = subprocess.run([sys.executable, "-c", RUNNER.replace("from station.cli import main",
                                                               "from station.cli import main\nimport h5py"), "[]"],
                         capture_output=True, text=True, check=True)
    assert "h5py" in json.loads(out.stdout.strip().splitlines()[-1])["loaded"]


def test_the_plain_descriptions_state_the_figures_they_name():
    """`station verify` and `station import` write their limits into DESCRIPTION as text (a plain
    string, so --help loads neither the verification nor the CSV reader): the same figures as
    the code that applies them."""
    from procedures.compensation.verify import ACCEPT_RATIO
    from procedures.io.csv_io import OPTIONAL_COLUMNS, REQUIRED_COLUMNS
    from procedures.io.ranges import MAX_ERROR_UM

    specs = _command_specs()
    assert f"(pass: <= {ACCEPT_RATIO:g})" in specs["verify"]["DESCRIPTION"]
    text = specs["import"]["DESCRIPTION"]
    assert f"Required columns: {', '.join(REQUIRED_COLUMNS)}; optional: {', '.join(OPTIONAL_COLUMNS)} (" in text
    assert f"|error_um| <= {MAX_ERROR_UM:g} um" in text


FIRST_POINT = """
import json, sys
from procedures.engine import events as ev
from station import progress
from station.cli import main

draw = progress.ConsoleProgress.handle
seen = []

def handle(self, event):  # the display sink, the last: every other sink has had the point
    if isinstance(event, ev.PointMeasured) and not seen:
        seen.append(sorted(sys.modules))
    return draw(self, event)

progress.ConsoleProgress.handle = handle
code = main(sys.argv[1:])
print(json.dumps({"code": code, "at_first_point": seen[0]}))
"""

NOT_BEFORE_THE_FIRST_POINT = ("sqlalchemy", "alembic", "mako", "scipy", "textual", "matplotlib", "fastapi",
                              "station.catalog.store", "station.catalog.readers")
"""The catalog (half a second of imports), the analyses and the UIs: none of them on the way to a
sweep's first point (issue 32: the first point within 1 s of the command starting)."""


def test_a_sweeps_first_point_waits_for_no_catalog_and_the_session_is_indexed_before_it_ends(tmp_path):
    """`station sweep --sim --time-scale 0` with catalog writes on: at its first point the process
    has loaded neither the catalog nor an analysis; once the command has ended, the catalog
    (<recordings_dir>/catalog.sqlite) holds the session."""
    out = tmp_path / "s.h5"
    env = {**os.environ, "STATION_CATALOG": "on"}
    done = subprocess.run([sys.executable, "-c", FIRST_POINT, "sweep", "--sim", "--time-scale", "0", "--legs", "1",
                           "--n-targets", "5", "--cycles", "1", "--out", str(out)],
                          capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["code"] == 0
    loaded = set(result["at_first_point"])
    assert {"station.services.wiring", "h5py", "pymodbus"} <= loaded  # the run was under way
    early = sorted({m if m.startswith("station.") else m.split(".")[0] for m in loaded
                    if m in NOT_BEFORE_THE_FIRST_POINT or m.split(".")[0] in NOT_BEFORE_THE_FIRST_POINT})
    assert not early, f"loaded before the first point: {early}"
    from station.catalog.store import Catalog

    catalog = Catalog(local=tmp_path / "runs" / "catalog.sqlite")
    try:
        with catalog.engine.connect() as conn:
            rows = conn.exec_driver_sql("SELECT kind, path, outcome FROM records").fetchall()
    finally:
        catalog.close()
    assert rows == [("session", str(out.resolve()), "completed")]


def test_the_deferred_catalog_sink_opens_at_the_second_point_or_at_close(tmp_path, monkeypatch):
    """CatalogSink.deferred: the catalog opened in a thread once a second point is measured (the
    first is on every sink's way out by then), or at close when there was none; the session
    indexed by the "catalog-index" thread; nothing at all with catalog writes off."""
    from procedures.engine import events as ev
    from station.catalog.writer import CatalogSink
    from station.services.config import StationConfig
    from tests.catalog.helpers import write_session

    monkeypatch.setenv("STATION_CATALOG", "on")
    cfg = StationConfig(recordings_dir=str(tmp_path / "runs"))
    session = write_session(tmp_path / "cal.h5")
    point = ev.PointMeasured(record={}, done=1, total=2)
    opened = []
    monkeypatch.setattr(CatalogSink, "_open", lambda self, real=CatalogSink._open: (opened.append(
        threading.current_thread().name), real(self))[1])

    sink = CatalogSink.deferred(cfg, session)
    sink.handle(ev.Message(text="start"))
    sink.handle(point)
    assert sink._opening is None and sink.catalog is None  # not on the first point's way
    sink.handle(point)
    sink._opening.join(60)
    assert opened == ["catalog-open"] and sink.catalog.local == tmp_path / "runs" / "catalog.sqlite"
    sink.close("completed")
    assert sink.thread.name == "catalog-index"
    sink.thread.join(60)
    assert len(sink.uids) == 1 and sink.uids[0].startswith("session:")
    sink.catalog.close()

    aborted = CatalogSink.deferred(cfg, write_session(tmp_path / "cut.h5"))  # no point: opened by close
    aborted.close("aborted")
    aborted.thread.join(60)
    assert opened == ["catalog-open"] * 2 and len(aborted.uids) == 1 and aborted.uids != sink.uids
    aborted.catalog.close()

    monkeypatch.setenv("STATION_CATALOG", "off")
    off = CatalogSink.deferred(cfg, session)
    off.handle(point)
    off.handle(point)
    off.close("completed")
    assert off.catalog is None and off.thread is None and opened == ["catalog-open"] * 2
