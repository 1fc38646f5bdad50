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

from drivers.sim.plant import PlantConfig
from procedures.errors import SchemaError
from procedures.fit import fit, load_model
from procedures.fit.model_io import model_to_json
from station.synth import synth_session
from tests.fuzz.budget import examples, fed


@functools.cache
def model_doc(method: str) -> dict:
    cfg = PlantConfig().only("backlash", "lead", "longwave", "noise", "run_offset")
    points = synth_session({1: cfg, 4: cfg}, np.linspace(-60, 60, 41), cycles=3, seed=5)
    return json.loads(model_to_json(fit(points, method), "runs/s.h5", "ab" * 32))


json_value = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10, 10), st.integers(), st.sampled_from([10**400, -(10**30)]),
              st.floats(allow_nan=False, allow_infinity=False), st.sampled_from([1e308, -1e308, 5e-324, 0.0, -0.0]),
              st.text(max_size=10)),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=8,
)


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


@st.composite
def damaged_model(draw) -> bytes:
    doc = copy.deepcopy(model_doc(draw(st.sampled_from(["default", "paper"]))))
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(doc) if p]
        where = draw(st.sampled_from(paths))
        parent = doc
        for k in where[:-1]:
            parent = parent[k]
        if draw(st.integers(0, 4)) == 0 and isinstance(parent, dict):
            del parent[where[-1]]
        else:
            parent[where[-1]] = draw(json_value)
        if not isinstance(doc, dict):
            break
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
