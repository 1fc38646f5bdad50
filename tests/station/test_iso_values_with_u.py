"""ISO 230-2 values are shown with their basis and their expanded uncertainty U wherever they are
shown (issue 22, item 5): `station iso230` (text and --json) and `station run` (`make sweep`)
print the U the ISO 230-2 report computes (procedures.reporting.iso230_report), on the same basis."""

from __future__ import annotations

import json
import re
from pathlib import Path

from procedures.io.recording.reader import read_session
from station.cli import main
from station.services.report_jobs import session_iso230

SAMPLE = Path(__file__).resolve().parents[2] / "recordings" / "calibration-6legs.h5"
U_LINE = re.compile(r"^  leg (\d): E ([\d.]+) \+/- ([\d.]+), M ([\d.]+) \+/- ([\d.]+), A ([\d.]+) \+/- ([\d.]+), "
                    r"B ([\d.]+) \+/- ([\d.]+), R ([\d.]+) \+/- ([\d.]+) um$")


def _u_lines(text: str) -> dict[int, tuple[float, ...]]:
    return {int(m.group(1)): tuple(float(g) for g in m.groups()[1:]) for line in text.splitlines()
            if (m := U_LINE.match(line))}


def test_iso230_prints_and_writes_u_beside_every_value(tmp_path, capsys):
    out = tmp_path / "iso.json"
    assert main(["iso230", str(SAMPLE), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "ISO 230-2 (normalised error), U with k = 2 (docs/uncertainty.md):" in text
    printed = _u_lines(text)
    report = session_iso230(read_session(SAMPLE))  # what station report writes into iso230-2.json
    assert sorted(printed) == [1, 2, 3, 4, 5, 6]
    for leg, values in printed.items():
        want = report["legs"][str(leg)]["values"]
        for i, name in enumerate(("E", "M", "A", "B", "R")):
            assert values[2 * i] == round(want[name]["value_um"], 3) and values[2 * i + 1] == round(want[name]["U_um"], 3)
            assert values[2 * i + 1] > 0
    doc = json.loads(out.read_text())
    for leg in range(1, 7):
        want = report["legs"][str(leg)]["values"]
        # the JSON's values and their U are the report's, on the same (normalised) basis
        assert doc["legs"][str(leg)]["E"] == want["E"]["value_um"]
        assert doc["expanded_uncertainty_um"][str(leg)] == {name: v["U_um"] for name, v in want.items()}


def test_station_run_prints_the_basis_and_u(tmp_path, capsys):
    out = tmp_path / "run.h5"
    assert main(["run", "--legs", "1", "--cycles", "2", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "error: normalised to 20 degC material temperature" in text
    assert "ISO 230-2 (normalised error), U with k = 2" in text
    printed = _u_lines(text)
    assert list(printed) == [1] and all(u > 0 for u in printed[1][1::2])
