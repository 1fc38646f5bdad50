"""Model files: round trip, deterministic content, corrupt or foreign files refused clearly."""

from __future__ import annotations

import json

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.synthetic import synth_session
from procedures.vocabulary import SchemaError
from procedures.fit import fit, load_model, save_model

TARGETS = np.linspace(-60, 60, 81)
SHA = "ab" * 32


@pytest.fixture(scope="module")
def points():
    cfg = PlantConfig().only("backlash", "lead", "longwave", "wobble", "noise", "run_offset")
    return synth_session({1: cfg, 3: cfg}, TARGETS, cycles=3, seed=11)


@pytest.fixture(scope="module", params=["default", "paper"])
def saved(request, points, tmp_path_factory):
    model = fit(points, request.param)
    path = tmp_path_factory.mktemp("m") / f"{request.param}.json"
    save_model(model, path, "runs/s.h5", SHA)
    return model, path


def test_round_trip_predicts_the_same(saved):
    model, path = saved
    back = load_model(path)
    assert back.method == model.method
    assert list(back.legs) == [1, 3]
    assert back.source == {"path": "runs/s.h5", "sha256": SHA}
    x = np.linspace(-70, 70, 57)  # also beyond the stroke: end values held
    for leg in (1, 3):
        for d in (1, -1):
            np.testing.assert_array_equal(back.predict_um(leg, x, d), model.predict_um(leg, x, d))
        assert back.legs[leg].stroke_mm == model.legs[leg].stroke_mm == (-60.0, 60.0)
        assert back.legs[leg].stats == model.legs[leg].stats
    np.testing.assert_array_equal(back.predict_um(1, [-70.0, 70.0], 1), model.predict_um(1, [-60.0, 60.0], 1))


def test_file_layout(saved):
    model, path = saved
    doc = json.loads(path.read_text())
    assert doc["format"] == "station-leg-error-model" and doc["version"] == 1
    assert doc["method"] == model.method
    assert doc["source"] == {"path": "runs/s.h5", "sha256": SHA}
    assert doc["created_utc"].endswith("Z")
    assert set(doc["legs"]) == {"1", "3"}
    leg = doc["legs"]["1"]
    assert leg["stroke_mm"] == [-60.0, 60.0]
    assert {"heldout_rms_um", "noise_floor_um", "range_before_um"} <= set(leg["stats"])


def test_identical_input_gives_identical_file_but_source_and_time(points, tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    save_model(fit(points), a, "one.h5", "1" * 64)
    save_model(fit(points), b, "two.h5", "2" * 64)
    da, db = json.loads(a.read_text()), json.loads(b.read_text())
    for d in (da, db):
        d.pop("source")
        d.pop("created_utc")
        d.pop("integrity")  # the hash of everything else, source and time included
    assert da == db
    # and byte for byte once those two are equal
    ta = a.read_text().replace("one.h5", "X").replace("1" * 64, "H")
    tb = b.read_text().replace("two.h5", "X").replace("2" * 64, "H")
    strip = lambda t: "\n".join(line for line in t.splitlines()  # noqa: E731
                                 if "created_utc" not in line and not line.startswith('    "sha256"'))
    assert strip(ta) == strip(tb)


def _mutate(path, tmp_path, fn, name="bad.json"):
    doc = json.loads(path.read_text())
    fn(doc)
    out = tmp_path / name
    out.write_text(json.dumps(doc))
    return out


def test_truncated_file_is_refused(saved, tmp_path):
    _, path = saved
    bad = tmp_path / "cut.json"
    bad.write_text(path.read_text()[:200])
    with pytest.raises(SchemaError) as err:
        load_model(bad)
    assert str(bad) in str(err.value) and "not valid JSON" in str(err.value)


def test_foreign_json_is_refused(tmp_path):
    bad = tmp_path / "other.json"
    bad.write_text(json.dumps({"format": "something-else", "version": 1}))
    with pytest.raises(SchemaError, match="not a leg-error model"):
        load_model(bad)
    bad.write_text("[1, 2, 3]")
    with pytest.raises(SchemaError, match="not a leg-error model"):
        load_model(bad)
    bad.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")
    with pytest.raises(SchemaError, match="this is an image, not a model"):
        load_model(bad)


def test_newer_version_is_refused(saved, tmp_path):
    _, path = saved
    bad = _mutate(path, tmp_path, lambda d: d.update(version=2))
    with pytest.raises(SchemaError, match="version 2 is not supported"):
        load_model(bad)


@pytest.mark.parametrize(
    "mutation, field",
    [
        (lambda d: d["legs"]["1"].pop("stroke_mm"), "legs.1.stroke_mm"),
        (lambda d: d["legs"]["1"].update(stroke_mm=[5.0, -5.0]), "legs.1.stroke_mm"),
        (lambda d: d["legs"]["1"]["stats"].update(n_points="many"), "legs.1.stats.n_points"),
        (lambda d: d.update(method="magic"), "method"),
        (lambda d: d["legs"].update({"one": d["legs"]["1"]}), "legs.one"),
        (lambda d: d.update(legs={}), "legs"),
    ],
)
def test_corrupt_field_is_named(saved, tmp_path, mutation, field):
    _, path = saved
    bad = _mutate(path, tmp_path, mutation)
    with pytest.raises(SchemaError) as err:
        load_model(bad)
    assert str(bad) in str(err.value) and field in str(err.value)


def test_corrupt_coefficients_are_refused(saved, tmp_path):
    model, path = saved
    if model.method == "default":
        key = "coefficients_um"
        bad = _mutate(path, tmp_path, lambda d: d["legs"]["3"]["model"][key].pop())
    else:
        key = "amplitude_um"
        bad = _mutate(path, tmp_path, lambda d: d["legs"]["3"]["model"][key].pop())
    with pytest.raises(SchemaError, match=f"legs.3.model.{key}"):
        load_model(bad)
    # NaN is not JSON, but Python's reader accepts the literal: it must still be refused
    text = path.read_text()
    doc = json.loads(text)
    doc["legs"]["1"]["model"][key][0] = float("nan")
    nan_file = tmp_path / "nan.json"
    nan_file.write_text(json.dumps(doc))
    with pytest.raises(SchemaError, match=rf"legs.1.model.{key}\[0\]"):
        load_model(nan_file)
