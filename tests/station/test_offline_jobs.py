"""The offline jobs in the one shape (issue 32 part 1): a request -> prepare (every refusal before
anything is read or written) -> run through the JobRunner -> an outcome naming what was written."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.vocabulary import InputError
from station.services.csv_jobs import ExportRequest, prepare_export
from station.services.fit_job import FitRequest, prepare_fit
from station.services.job import JobRunner
from procedures.synthetic import synth_session
from tests.tooling import write_points_session

CFG = PlantConfig().only("backlash", "lead", "noise")


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    pts = synth_session({1: CFG}, np.linspace(-90, 90, 31), cycles=2, seed=3)
    return write_points_session(tmp_path_factory.mktemp("s") / "s.h5", pts)


def test_a_refusal_comes_before_the_session_is_read(tmp_path):
    with pytest.raises(InputError, match="--params 5: the number of cosine terms applies to --method paper only"):
        prepare_fit(FitRequest(tmp_path / "missing.h5", tmp_path / "m.json", params=5))
    assert not list(tmp_path.iterdir())


def test_the_fit_and_the_export_run_through_the_job_runner(session, tmp_path):
    runner = JobRunner()
    fit = runner.run(prepare_fit(FitRequest(session, tmp_path / "m.json", legs="1")))
    assert fit.ok and fit.status == "done" and fit.outputs == [tmp_path / "m.json"] and (tmp_path / "m.json").is_file()
    assert list(fit.data.model.legs) == [1] and fit.data.notes == []  # completed, no table active: nothing to note
    assert fit.lines == fit.data.basis_lines and fit.lines[0].startswith("error:")
    export = runner.run(prepare_export(ExportRequest(session, tmp_path / "s.csv")))
    assert export.ok and export.outputs == [tmp_path / "s.csv"]
    rows = (tmp_path / "s.csv").read_text().strip().splitlines()
    assert export.lines[0].startswith(f"exported {len(rows) - 1} points to {tmp_path / 's.csv'}")
    with pytest.raises(InputError, match="exists; add --force"):  # the output check is prepare's
        prepare_export(ExportRequest(session, tmp_path / "s.csv"))
    assert not runner.busy
