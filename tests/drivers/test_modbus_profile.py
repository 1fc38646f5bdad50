"""Drive profile loading/validation and the register codec."""

from __future__ import annotations

import random
import struct
from pathlib import Path

import pytest

from drivers.modbus.codec import CodecError, crc16_modbus, decode_ascii, decode_int, encode_ascii, encode_int
from drivers.modbus.profile import DEFAULT_PROFILE, DriveProfile, ProfileError


@pytest.mark.parametrize("typ, fmt", [("u16", "H"), ("i16", "h"), ("u32", "I"), ("i32", "i")])
@pytest.mark.parametrize("value", [0, 1, -1, 32767, -32768, 65535, 2**31 - 1, -(2**31), 123456789, -987654])
def test_int_codec_matches_struct(typ, fmt, value):
    try:
        packed = struct.pack(">" + fmt, value)
    except struct.error:
        with pytest.raises(CodecError):
            encode_int(value, typ)
        return
    words = list(struct.unpack(f">{len(packed) // 2}H", packed))
    assert encode_int(value, typ, "big") == words
    assert decode_int(words, typ, "big") == value
    assert encode_int(value, typ, "little") == words[::-1]
    assert decode_int(words[::-1], typ, "little") == value


def test_ascii_codec():
    assert encode_ascii("AB", 2) == [0x4142, 0]
    assert decode_ascii(encode_ascii("LegServo-402", 8)) == "LegServo-402"
    with pytest.raises(CodecError):
        encode_ascii("x" * 17, 8)


def _crc_reference(data: bytes) -> int:
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def test_crc16_modbus_matches_the_catalogue_definition():
    assert _crc_reference(b"123456789") == 0x4B37  # CRC-16/MODBUS check value
    rng = random.Random(7)
    for n in (0, 1, 2, 5, 123, 1024):
        regs = [rng.randrange(0x10000) for _ in range(n)]
        assert crc16_modbus(regs) == _crc_reference(struct.pack(f">{n}H", *regs))
    regs = [1, 2, 3]
    assert crc16_modbus(regs) != crc16_modbus([1, 2, 2])


def test_default_profile_layout(profile):
    assert profile.address("position_actual") == 111
    mv = profile.blocks["move_command"]
    assert mv.names[0] == "controlword" and mv.words == 3
    st = profile.blocks["status"]
    assert st.words <= 125 and {"statusword", "position_actual", "following_error", "fault_code", "axial_load",
                                "active_bank", "table_enable"} <= set(st.names)
    assert profile.limits.soft_min_mm == -95.0 and profile.limits.soft_max_mm == 95.0
    t = profile.table
    assert t.max_points == 512 and t.max_correction_um == 300.0
    assert round(t.max_correction_um / t.entry_scale_um) <= 32767
    for state in ("not_ready", "switch_on_disabled", "ready_to_switch_on", "switched_on", "operation_enabled",
                  "quick_stop_active", "fault"):
        assert profile.state_of(profile.statusword_of(state)) == state


def _broken(tmp_path: Path, old: str, new: str) -> Path:
    text = DEFAULT_PROFILE.read_text()
    assert old in text
    p = tmp_path / "broken.toml"
    p.write_text(text.replace(old, new, 1))
    return p


@pytest.mark.parametrize(
    "old, new, words",
    [
        ('position_actual      = { address = 111, type = "i32"', 'position_actual      = { address = 111, type = "f32"',
         "[registers.position_actual] type"),
        ("controlword          = { address = 100,", "controlword          = { address = 99,", "[blocks.move_command]"),
        ("following_error      = { address = 113,", "following_error      = { address = 112,", "overlaps"),
        ('word_order = "big"', 'word_order = "middle"', "[profile] word_order"),
        ("max_correction_um = 300.0", "max_correction_um = 400.0", "[table] max_correction_um"),
        ("bank_base = [1000, 3000]", "bank_base = [1000, 1500]", "overlaps"),
        ("soft_min_mm = -95.0", "soft_min_mm = 96.0", "[limits] soft_min_mm"),
        ('name = "soft_limit"', 'name = "limit"', "soft_limit"),
        ("serial               = {", "serialnumber         = {", "[blocks.identity] unknown register(s) serial"),
        ("statusword           = {", "statusword_x         = {", "[registers] missing statusword"),
    ],
)
def test_profile_errors_name_file_and_key(tmp_path, old, new, words):
    p = _broken(tmp_path, old, new)
    with pytest.raises(ProfileError) as info:
        DriveProfile.load(p)
    text = str(info.value)
    assert str(p) in text and words in text, text


def test_missing_or_invalid_profile_file(tmp_path):
    with pytest.raises(ProfileError, match="not found"):
        DriveProfile.load(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[profile\n")
    with pytest.raises(ProfileError, match="not valid TOML"):
        DriveProfile.load(bad)


def test_little_word_order_profile_round_trips(tmp_path):
    p = _broken(tmp_path, 'word_order = "big"', 'word_order = "little"')
    prof = DriveProfile.load(p)
    r = prof.register("position_actual")
    assert r.encode(-1.5) == encode_int(-1_500_000, "i32", "little")
    assert r.decode(r.encode(-1.5)) == pytest.approx(-1.5)


def test_register_map_doc_matches_the_profile(profile):
    doc = (Path(__file__).resolve().parents[2] / "docs" / "register-map.md").read_text()
    rows = [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in doc.splitlines() if ln.startswith("| ")]
    seen = set()
    for cells in rows:
        if len(cells) >= 3 and cells[0].isdigit() and cells[1] in profile.registers:
            r = profile.registers[cells[1]]
            typ = r.type if r.type != "ascii" else f"ascii x{r.words}"
            assert (int(cells[0]), cells[2]) == (r.address, typ), f"docs row {cells[:3]} vs profile {r}"
            seen.add(r.name)
        if len(cells) >= 3 and cells[0].startswith("+") and cells[1] in profile.table.header:
            h = profile.table.header[cells[1]]
            assert (int(cells[0][1:]), cells[2]) == (h.address, h.type), f"docs header row {cells[:3]}"
            seen.add("header." + h.name)
        if cells and cells[0].startswith("0x") and len(cells) >= 2:
            code = int(cells[0], 16)
            if code in profile.faults:
                assert profile.faults[code].name == cells[1]
                seen.add(f"fault.{code}")
    assert set(profile.registers) <= seen, f"undocumented registers: {set(profile.registers) - seen}"
    assert {f"header.{n}" for n in profile.table.header} <= seen
    assert {f"fault.{c}" for c in profile.faults} <= seen
    assert f"-r {profile.address('position_actual')} -t 4:int -B" in doc
