"""Fuzzing the model JSON reader (procedures/fit/model_io.py load_model).

Valid model files (both methods, from a real fit) are damaged: a value anywhere in the tree
replaced by another JSON value, a key deleted, the text cut short or bytes flipped.
Property: a model whose predictions are finite numbers (a loaded model is usable), or
SchemaError naming the file; never another exception.
"""

from __future__ import annotations

import copy
import functools
import json
import math
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import example, given, settings, strategies as st

from drivers.plant.leg import PlantConfig
from procedures.vocabulary import SchemaError
from procedures.fit import fit, load_model
from procedures.fit.model_io import model_to_json
from procedures.synthetic import synth_session
from tests.fuzz.budget import examples, fed
from tests.fuzz.jsondamage import damaged_json, json_value


@functools.cache
def model_doc(method: str) -> dict:
    cfg = PlantConfig().only("backlash", "lead", "longwave", "noise", "run_offset")
    points = synth_session({1: cfg, 4: cfg}, np.linspace(-60, 60, 41), cycles=3, seed=5)
    return json.loads(model_to_json(fit(points, method), "runs/s.h5", "ab" * 32))


@st.composite
def damaged_model(draw) -> bytes:
    doc = damaged_json(draw, model_doc(draw(st.sampled_from(["default", "paper"]))), 3)
    text = json.dumps(doc).encode()  # Python's json writes NaN/Infinity too: the reader must refuse them
    cut = draw(st.sampled_from([None, None, None, "cut", "flip"]))
    if cut == "cut":
        text = text[: draw(st.integers(0, len(text)))]
    elif cut == "flip":
        i = draw(st.integers(0, len(text) - 1))
        text = text[:i] + bytes([draw(st.integers(0, 255))]) + text[i + 1:]
    return text


def _usable(model) -> None:
    x = np.linspace(-100, 100, 9)
    for leg in model.legs:
        for d in (1, -1):
            with np.errstate(all="ignore"):
                y = np.asarray(model.predict_um(leg, x, d), dtype=float)
            assert np.all(np.isfinite(y)), f"leg {leg} predicts {y}"


@settings(max_examples=examples(200))
@given(st.one_of(damaged_model(), st.binary(max_size=100), json_value.map(lambda v: json.dumps(v).encode())))
@example(b"")
@example(b'{"format": "station-leg-error-model", "version": 1, "method": "default", "legs": {"1": []}}')
@example(b'{"format": "station-leg-error-model", "version": 1, "method": "default", "source": {}, "legs": {"\xd9\xa1": {}}}')
def test_load_model_fuzzed(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "model.json"
        path.write_bytes(data)
        try:
            model = load_model(path)
        except SchemaError as exc:
            fed("model JSON (load_model)", refused=True)
            assert str(path) in str(exc), exc
            return
        fed("model JSON (load_model)")
        assert model.legs and set(model.legs) <= {1, 2, 3, 4, 5, 6}
        _usable(model)


def test_valid_models_load():
    """The fuzzer's seeds are good files (else every damaged one would be refused anyway)."""
    with tempfile.TemporaryDirectory() as d:
        for method in ("default", "paper"):
            path = Path(d) / f"{method}.json"
            path.write_text(json.dumps(model_doc(method)))
            model = load_model(path)
            assert sorted(model.legs) == [1, 4]
            _usable(model)
            assert math.isfinite(float(model.predict_um(1, [0.0], 1)[0]))


def test_an_integer_beyond_any_float_is_refused_naming_the_field(tmp_path):
    """Found by fuzzing: a JSON integer too large for a float (center_mm = 10**400) raised
    OverflowError; it is refused as not a finite number, naming the field."""
    doc = copy.deepcopy(model_doc("default"))
    doc["legs"]["1"]["model"]["basis"]["center_mm"] = 10**400
    path = tmp_path / "model.json"
    path.write_text(json.dumps(doc))
    try:
        load_model(path)
    except SchemaError as exc:
        assert f"{path}: legs.1.model.basis.center_mm: not a finite number" in str(exc)
    else:
        raise AssertionError("a model with center_mm = 10**400 was accepted")
    doc = copy.deepcopy(model_doc("paper"))
    doc["legs"]["4"]["model"]["amplitude_um"][0] = -(10**400)
    path.write_text(json.dumps(doc))
    try:
        load_model(path)
    except SchemaError as exc:
        assert "legs.4.model.amplitude_um[0]" in str(exc)
    else:
        raise AssertionError("a model with amplitude_um = -10**400 was accepted")
