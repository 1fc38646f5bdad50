"""The platform experiment's inputs and report live in station.services.platform_jobs, which both
`station platform` and the terminal UI's Platform page use (the UI imports no command module)."""

import numpy as np

from station.services import platform_jobs
from tests.tooling import defines, imported_names


def test_the_command_and_the_ui_share_the_inputs_and_the_report():
    # by the command's imports (inside run(): `station platform --help` loads none of it), no copy of its own
    # both front ends run the one job (prepare_platform: inputs by load_errors, report by write_report)
    for front in ("station.commands.platform", "station.tui.screens.platform"):
        names = imported_names(front)
        assert names["prepare_platform"] == "station.services.platform_jobs.prepare_platform"
        for name in ("load_errors", "write_report", "run_measurements", "prepare_platform"):
            assert not defines(front, name)
    for name in ("load_errors", "write_report"):
        assert getattr(platform_jobs, name).__module__ == "station.services.platform_jobs"
        assert name in platform_jobs.PreparedPlatform.run.__code__.co_names


def test_a_model_held_in_memory_is_measured_on_its_own_basis(tmp_path):
    """The UI's path (`model_errors`, a model fitted on Results): the recording's error on the
    model's basis, the same figures as the experiment run straight on those points; a model that
    records no basis (fitted before normalisation existed) is measured on the raw error; --raw
    against a normalised model is refused."""
    import pytest

    from procedures.vocabulary import InputError
    from procedures.fit import fit
    from procedures.metrology.thermal import error_basis
    from procedures.platform.experiment import RecordedLegErrors, run_measurements
    from procedures.platform.geometry import default_geometry
    from procedures.io.recording.reader import read_session
    from tests.tooling import default_legs_points, write_points_session

    path = tmp_path / "s.h5"
    points = default_legs_points(range(1, 7), 2, 6.0, 0)
    points["material_temp_c"] = 24.0 + 2.0 * np.arange(len(points)) / len(points)  # a warm leg, 4-6 K off 20 degC
    write_points_session(path, points)
    session = read_session(path)
    at_20 = error_basis(session)[0]
    model = fit(at_20, "default")
    ranges = {}
    for basis, pts in (("normalised", at_20), ("raw", session.points)):
        model.options["error_basis"] = {"normalised": basis == "normalised"}
        main, other, inputs = platform_jobs.model_errors(model, session, path, None, model_label="in memory")
        assert inputs["error_basis"]["basis"] == basis
        _, got = run_measurements(default_geometry(), main, other, poses=150, seed=2)
        direct = RecordedLegErrors(pts, predicted_um=model.predict_um, measurement="mean")
        _, want = run_measurements(default_geometry(), direct, poses=150, seed=2)
        assert got["legs"]["all"]["range_compensated"] == pytest.approx(want["legs"]["all"]["range_compensated"],
                                                                        rel=1e-12, abs=1e-12)
        ranges[basis] = got["legs"]["all"]["range_compensated"]
    # a model of the 20 degC error applied to the raw error of a leg 4-6 K warm leaves the expansion in
    assert ranges["raw"] > ranges["normalised"] + 1.0
    model.options["error_basis"] = {"normalised": True}
    with pytest.raises(InputError, match="in memory was fitted to the error normalised to 20 degC"):
        platform_jobs.model_errors(model, session, path, None, model_label="in memory", raw=True)
