"""Whatever a controller file or a mapped import holds, the readers answer with a result or an
InputError naming the file; never another exception (no traceback reaches a user)."""

from __future__ import annotations

import string

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from procedures.compensation.controllers import ecmc, heidenhain, linuxcnc, siemens840d, twincat
from procedures.vocabulary import InputError
from procedures.io.import_map import convert, load_map

# text built from the formats' own vocabulary, so the fuzzing gets past the first line
WORDS = st.sampled_from(["BEGIN", "X.COM", "MM", "NR", "AXISPOS", "X", "BACKLASH", "[END]", "PREC=5", "PREC=x",
                         "#", "kw.ssfk.table[0].setpoint", "kw.ssfk.table[1].pos", "kw.ssfk.table[0].neg",
                         "kw.ssfk.unit", "kw.ssfk.bilateral", "kw.ssfk.kw_nr_max", "$AN_CEC[0,0]=",
                         "$AN_CEC_STEP[0]=", "$AN_CEC_MIN[0]=", "$AN_CEC_MAX[0]=", "$AN_CEC_DIRECTION[0]=",
                         "$AN_CEC_INPUT_AXIS[0]=(AX1)", "$AN_CEC_OUTPUT_AXIS[0]=(AX1)", "$AA_ENC_COMP[0,0,AX1]=",
                         "1", "0", "-1", "1e308", "nan", "inf", "0.5", "-90", "90", ",", ";", "\t", "\x00", "é"])
LINE = st.lists(st.one_of(WORDS, st.text(string.printable, max_size=6)), max_size=6).map(" ".join)
FILE = st.lists(LINE, max_size=12).map("\n".join)

READERS = [lambda p: heidenhain.load(p), lambda p: twincat.load(p), lambda p: ecmc.load(p),
           lambda p: siemens840d.load(p), lambda p: linuxcnc.load(p, 0)]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=FILE, which=st.integers(0, len(READERS) - 1))
def test_controller_readers_fail_only_with_input_errors(tmp_path, text, which):
    path = tmp_path / "f.txt"
    path.write_text(text, encoding="utf-8")
    try:
        READERS[which](path)
    except InputError as exc:
        assert str(path) in str(exc)


MAP = """
[file]
delimiter = "{d}"
decimal = "{dec}"
[columns]
target = 1
error = 2
direction = 3
[defaults]
leg = 1
"""


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=FILE, d=st.sampled_from([";", "\\t", "whitespace", "|"]), dec=st.sampled_from([".", ","]))
def test_mapped_import_fails_only_with_input_errors(tmp_path, text, d, dec):
    m = tmp_path / "m.toml"
    m.write_text(MAP.format(d=d, dec=dec))
    data = tmp_path / "d.csv"
    data.write_text(text, encoding="utf-8")
    try:
        convert(data, load_map(m))
    except InputError as exc:
        assert str(data) in str(exc)


@pytest.mark.parametrize("blob", [b"\xff\xfe\x00garbage", b"\x00" * 20])
def test_binary_files_are_refused(tmp_path, blob):
    path = tmp_path / "b.bin"
    path.write_bytes(blob)
    for read in READERS:
        with pytest.raises(InputError):
            read(path)
