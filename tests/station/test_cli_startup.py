"""`station X --help`, an argument error and a refusal load nothing heavy (issue 32, deliverable 6):
the command modules import what a run needs inside run(). Checked on the modules a fresh process
has loaded, not on time (bench/bench_startup.py prints the times)."""

from __future__ import annotations

import json
import subprocess
import sys

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
