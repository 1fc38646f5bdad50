"""Fuzzing the readers of controller files (procedures/compensation/controllers/: LinuxCNC, SINUMERIK 840D,
Heidenhain, TwinCAT, ecmc) and of mapped imports (procedures/io/import_map.py: the map TOML and the
foreign data file).

Valid files written by the station's own writers (the documented example maps and their data)
are damaged line by line, token by token and byte by byte; random bytes too. Property: a table
whose applied correction is finite everywhere (a mapped import: interchange CSV text), or
InputError naming the file; never another exception.
"""

from __future__ import annotations

import copy
import functools
import math
import tempfile
import tomllib
from pathlib import Path

import numpy as np
from hypothesis import example, given, settings, strategies as st

from procedures.compensation.controllers import FORMATS, module
from procedures.vocabulary import InputError
from procedures.io.import_map import convert, load_map
from procedures.compensation.table import CompTable, LegTable
from tests.fuzz import tomlgen
from tests.fuzz.budget import examples, fed
from tests.fuzz.tomlgen import damaged

MAPS = Path(__file__).resolve().parents[2] / "docs" / "import-maps"
CONTROLLERS = FORMATS + ("linuxcnc",)
token = st.one_of(st.sampled_from(["", "nan", "inf", "-inf", "1e400", "9" * 400, "0x10", "1,5", "abc", "=", ";", "(", "%",
                                   "N10", "$AA", "-0", "1e-400"]),
                  st.floats().map(repr), st.integers(-10**6, 10**6).map(str), st.text(max_size=8))


@functools.cache
def controller_files() -> dict[str, list[tuple[str, bytes]]]:
    n = 9
    table = CompTable({leg: LegTable(leg, -40.0, 10.0, tuple(np.linspace(-5, 5, n) * leg), tuple(np.linspace(4, -6, n)))
                       for leg in (1, 2)})
    out = {}
    with tempfile.TemporaryDirectory() as d:
        for name in CONTROLLERS:
            folder = Path(d) / name
            paths = module(name).write(table, folder)
            out[name] = [(Path(p).name, Path(p).read_bytes()) for p in paths]
    return out


@st.composite
def damaged_lines(draw, seed: bytes) -> bytes:
    lines = seed.split(b"\n")
    for _ in range(draw(st.integers(1, 3))):
        if not lines:
            break
        i = draw(st.integers(0, len(lines) - 1))
        how = draw(st.sampled_from(["token", "drop", "dup", "swap", "byte", "cut"]))
        if how == "token":
            words = lines[i].split()
            if words:
                words[draw(st.integers(0, len(words) - 1))] = draw(token).encode("utf-8", "surrogatepass")
            lines[i] = b" ".join(words)
        elif how == "drop":
            del lines[i]
        elif how == "dup":
            lines.insert(i, lines[i])
        elif how == "swap" and i + 1 < len(lines):
            lines[i], lines[i + 1] = lines[i + 1], lines[i]
        elif how == "byte" and lines[i]:
            j = draw(st.integers(0, len(lines[i]) - 1))
            lines[i] = lines[i][:j] + bytes([draw(st.integers(0, 255))]) + lines[i][j + 1:]
        elif how == "cut":
            lines = lines[:i]
    return b"\n".join(lines)


@st.composite
def controller_case(draw):
    name = draw(st.sampled_from(CONTROLLERS))
    fname, seed = draw(st.sampled_from(controller_files()[name]))
    data = draw(st.one_of(damaged_lines(seed), damaged_lines(seed), st.binary(max_size=120)))
    return name, fname, data


@settings(max_examples=examples(300))
@given(controller_case())
@example(("linuxcnc", "joint0.comp", b"nan -40.005 -39.996\n-30 -30.00375 -29.99725\n"))  # found: NaN corrections
@example(("linuxcnc", "joint0.comp", b"-40 -40.005 -39.996\n-30 inf -29.99725\n"))
@example(("twincat", "achskw1.lis", b"kw.ssfk.table[0].setpoint " + b"9" * 400 + b"\nkw.ssfk.table[1].setpoint 0\n"
          b"kw.ssfk.table[0].pos 1\nkw.ssfk.table[1].pos 2\n"))  # found: OverflowError
def test_controller_readers_fuzzed(case):
    name, fname, data = case
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / fname
        path.write_bytes(data)
        try:
            comp = module(name).load(path)
        except InputError as exc:
            fed(f"controller file ({name}.load)", refused=True)
            assert str(path) in str(exc), exc
            return
        fed(f"controller file ({name}.load)")
        x = np.linspace(-100, 100, 21)
        for direction in (1, -1):
            with np.errstate(all="ignore"):
                y = np.asarray(comp.applied_mm(x, direction), dtype=float)
            assert y.shape == x.shape and np.all(np.isfinite(y)), f"{name}: applied {y}"


def test_controller_seeds_load():
    for name, files in controller_files().items():
        with tempfile.TemporaryDirectory() as d:
            for fname, data in files:
                path = Path(d) / fname
                path.write_bytes(data)
                comp = module(name).load(path)
                assert math.isfinite(float(np.asarray(comp.applied_mm([0.0], 1), dtype=float)[0]))


MAP_SEEDS = {name: tomllib.loads((MAPS / f"{name}.toml").read_text()) for name in ("renishaw-like", "api-xd-like")}


@st.composite
def mapped_case(draw):
    name = draw(st.sampled_from(sorted(MAP_SEEDS)))
    data = (MAPS / f"{name}.csv").read_bytes()
    map_text = draw(st.one_of(st.just(tomlgen.dumps(copy.deepcopy(MAP_SEEDS[name])).encode()), damaged(MAP_SEEDS[name])))
    data = draw(st.one_of(st.just(data), damaged_lines(data), st.binary(max_size=100)))
    return map_text, data


@settings(max_examples=examples(200))
@given(mapped_case())
def test_mapped_import_fuzzed(case):
    map_text, data = case
    with tempfile.TemporaryDirectory() as d:
        map_path, data_path = Path(d) / "map.toml", Path(d) / "data.csv"
        map_path.write_bytes(map_text)
        data_path.write_bytes(data)
        try:
            m = load_map(map_path)
        except InputError as exc:
            fed("import map TOML (load_map)", refused=True)
            assert str(map_path) in str(exc), exc
            return
        fed("import map TOML (load_map)")
        try:
            conv = convert(data_path, m)
        except InputError as exc:
            fed("mapped import data (convert)", refused=True)
            assert str(data_path) in str(exc) or str(map_path) in str(exc), exc
            return
        fed("mapped import data (convert)")
        assert conv.csv_text.startswith("leg,run,direction,target_mm,error_um")
        rows = conv.csv_text.splitlines()[1:]
        assert rows and len(rows) == len(conv.source_lines)
