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


@pytest.mark.parametrize(
    "old, new, words",
    [
        ("max_read_words = 125", "max_read_words = 126", "[protocol] max_read_words: must be an integer in 1..125"),
        ("max_write_words = 123", "max_write_words = 0", "[protocol] max_write_words"),
        ("min_frame_gap_ms = 0.0", "min_frame_gap_ms = -1", "[protocol] min_frame_gap_ms"),
        ("address_base = 0 ", "address_base = 2 ", "[protocol] address_base"),
        ('unit_ids = "leg"', 'unit_ids = "auto"', "[protocol] unit_ids"),
        ('unit_ids = "leg"', "unit_ids = { 1 = 300 }", "[protocol.unit_ids] 1: unit id must be an integer 1..247"),
        ('move_write = "single"', 'move_write = "double"', "[protocol] move_write"),
        ('set_point_latch = "level"', 'set_point_latch = "rising"', "[protocol] set_point_latch"),
        ("max_read_words = 125", "max_read_words = 125\nframe_gap = 3", "[protocol] unknown key(s) frame_gap"),
        ("max_write_words = 123", "max_write_words = 2", "[blocks.move_command] spans 3 registers"),
        ('kind = "banks" ', 'kind = "none"\nnote = "none here" ', "[table] kind = \"none\" takes only a note"),
        ("address_base = 0 ", "address_base = 1 ", "[registers.vendor] address: must be an integer in 1..65536, got 0"),
        ('unit = "mm", access = "r" }\nfollowing_error', 'unit = "mm", access = "r", object = 6064 }\nfollowing_error',
         "[registers.position_actual] object"),
        ('position_actual      = { address = 111, type = "i32", scale = 1e-6,',
         'position_actual      = { address = 111, type = "i32", scale = "counts_per_mm",', "not a key of [scaling]"),
        ('move_write = "single"', 'move_write = "single"\nmode_of_operation = 1', "mode_of_operation and [registers.modes_of_operation]"),
    ],
)
def test_protocol_keys_are_checked_naming_file_and_key(tmp_path, old, new, words):
    p = _broken(tmp_path, old, new)
    with pytest.raises(ProfileError) as info:
        DriveProfile.load(p)
    text = str(info.value)
    assert str(p) in text and words in text, text


def test_a_profile_without_a_table_says_why(tmp_path):
    text = DEFAULT_PROFILE.read_text()
    start = text.index("[table]\n")
    end = text.index("[table.header]")
    end = text.index("\n\n", text.index("valid", end)) if "\n\n" in text[end:] else len(text)
    body = text[:start] + '[table]\nkind = "none"\nnote = "no table in this drive"\n' + text[end:]
    p = tmp_path / "notable.toml"
    p.write_text(body)
    prof = DriveProfile.load(p)
    assert prof.table is None and prof.table_note == "no table in this drive"
    from drivers.modbus.client import table_spec
    assert table_spec(prof) is None
    p.write_text(body.replace('note = "no table in this drive"\n', ""))
    with pytest.raises(ProfileError, match=r"\[table\] note: say why"):
        DriveProfile.load(p)


def test_scaling_address_base_and_runs(tmp_path):
    """A register's scale may name [scaling] (counts per unit); address_base = 1 shifts every
    printed address down by one; reads group contiguous registers up to the drive's limit."""
    text = DEFAULT_PROFILE.read_text()
    text = text.replace("[limits]\n", "[scaling]\nposition_counts_per_mm = 1e6\n\n[limits]\n", 1)
    text = text.replace('position_actual      = { address = 111, type = "i32", scale = 1e-6,',
                        'position_actual      = { address = 111, type = "i32", scale = "position_counts_per_mm",')
    text = text.replace("max_read_words = 125", "max_read_words = 8")
    p = tmp_path / "scaled.toml"
    p.write_text(text)
    prof = DriveProfile.load(p)
    r = prof.register("position_actual")
    assert r.address == 111 and r.scale == pytest.approx(1e-6)
    assert r.decode(r.encode(-12.345678)) == pytest.approx(-12.345678, abs=1e-9)
    runs = prof.runs(prof.blocks["status"].names)
    assert [w for _, w, _ in runs] == [8, 2]  # 10 words in reads of at most 8, no value split
    assert [n for _, _, ns in runs for n in ns] == list(prof.blocks["status"].names)

    kinco = (DEFAULT_PROFILE.parent / "kinco_fd.toml").read_text()
    assert kinco.count("address_base = 0 ") == 1
    p1 = tmp_path / "kinco_base1.toml"
    p1.write_text(kinco.replace("address_base = 0 ", "address_base = 1 "))
    base0 = DriveProfile.load(DEFAULT_PROFILE.parent / "kinco_fd.toml")
    base1 = DriveProfile.load(p1)
    for name in base0.registers:  # the same printed numbers, one lower on the wire
        assert base1.address(name) == base0.address(name) - 1


@pytest.mark.parametrize("name", ["default", "delta_asda_a2", "kinco_fd"])
def test_run_decoder_gives_the_values_of_register_by_register_decoding(name):
    """The status run's one-call decoder agrees with Register.decode on every value, extremes
    of each type included (sign bits, the top of 32-bit words)."""
    prof = DriveProfile.load(Path(__file__).resolve().parents[2] / "drivers" / "modbus" / "profiles" / f"{name}.toml")
    rnd = random.Random(7)
    for address, count, names in prof.runs(prof.blocks["status"].names):
        decode = prof.run_decoder(names)
        for words in ([0] * count, [0xFFFF] * count, [0x8000] * count, [0x7FFF] * count,
                      *([rnd.randrange(0x10000) for _ in range(count)] for _ in range(200))):
            want = {n: prof.registers[n].decode(words[prof.registers[n].address - address:
                                                      prof.registers[n].end - address]) for n in names}
            got = decode(words)
            assert got == want and [type(v) for v in got.values()] == [type(want[n]) for n in got]
