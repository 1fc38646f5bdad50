"""Read Device Identification (Modbus function 43, MEI type 14) on the simulated drive, over real
TCP (and RTU on a pty): read by the station's client and by an independent master (modbus-tk, which builds the
request and hands back the raw reply; mbpoll has no function 43). A drive whose profile says it
does not answer is refused with exception 01, and the station then names the drive from the
config instead."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from drivers.modbus.client import RequestRefused
from drivers.modbus.profile import DEFAULT_PROFILE, DriveProfile, ProfileError

from modbus_tk import defines as cst  # the independent peer: a test dependency, never skipped
from modbus_tk import modbus_tcp
from modbus_tk.exceptions import ModbusError

pytestmark = pytest.mark.filterwarnings("ignore:isSet:DeprecationWarning")  # inside modbus-tk


def _profile_without_device_id(tmp_path: Path) -> DriveProfile:
    text = DEFAULT_PROFILE.read_text(encoding="utf-8")
    assert "device_identification = true" in text
    p = tmp_path / "no-43.toml"
    p.write_text(text.replace("device_identification = true", "device_identification = false"), encoding="utf-8")
    return DriveProfile.load(p)


def _parse_objects(raw: bytes) -> dict[int, str]:
    """The objects of a 43/14 reply's data (after the function code), parsed by the Modbus
    specification (MEI type, read code, conformity, more follows, next id, count, objects)."""
    mei, _code, _conformity, _more, _next, count = struct.unpack(">6B", raw[:6])
    assert mei == 0x0E
    objects, at = {}, 6
    for _ in range(count):
        oid, length = raw[at], raw[at + 1]
        objects[oid] = raw[at + 2 : at + 2 + length].decode("ascii")
        at += 2 + length
    assert at == len(raw), "bytes after the last object"
    return objects


def _tk_read(url: str, unit: int) -> bytes:
    host, port = url.removeprefix("tcp://").split(":")
    master = modbus_tcp.TcpMaster(host=host, port=int(port), timeout_in_sec=2.0)
    try:
        return master.execute(unit, cst.DEVICE_INFO, 0, output_value=(1, 0), returns_raw=True)
    finally:
        master.close()


@pytest.mark.parametrize("rtu", [False, True], ids=["tcp", "rtu"])
def test_client_reads_the_basic_objects_and_the_serial(sim_drives, profile, rtu):
    sd = sim_drives(rtu=rtu)
    ident = profile.identity
    axis = sd.axis(3)
    objects = axis.bus.read_device_identification(3)  # one client per line: a pty takes one
    assert objects == {0: ident["vendor"], 1: ident["product"], 2: ident["firmware"]}
    got = axis.drive_identity()
    assert got == {"vendor": ident["vendor"], "product_code": ident["product"], "revision": ident["firmware"],
                   "serial": f"{ident['serial_prefix']}-0003", "source": "modbus-device-id"}


def test_an_independent_master_reads_the_same_objects(sim_drives, profile):
    sd = sim_drives()
    for unit in (1, 6):
        objects = _parse_objects(_tk_read(sd.url, unit))
        assert objects == {0: profile.identity["vendor"], 1: profile.identity["product"],
                           2: profile.identity["firmware"]}


def test_a_drive_without_the_function_answers_exception_01(sim_drives, tmp_path, monkeypatch):
    no43 = _profile_without_device_id(tmp_path)
    sd = sim_drives()
    sd.server.stop()  # the same plants behind a server with the other profile
    from drivers.sim.drive_server import SimDriveServer

    server = SimDriveServer(sd.plants, sd.clock, no43, lock=sd.lock)
    try:
        url = f"tcp://127.0.0.1:{server.start_tcp('127.0.0.1', 0)}"
        bus = sd.bus(url=url)
        with pytest.raises(RequestRefused) as exc:
            bus.read_device_identification(2)
        assert exc.value.exception_code == 1
        with pytest.raises(ModbusError) as tk:
            _tk_read(url, 2)
        assert tk.value.get_exception_code() == 1
        # the station does not ask such a drive: the profile's identity, said to come from the config
        before = bus.transactions
        from drivers.modbus.client import ModbusServoAxis

        got = ModbusServoAxis(bus, 2, no43).drive_identity()
        assert got["source"] == "config" and got["revision"] is None
        assert got["vendor"] == no43.identity["vendor"] and got["serial"] == f"{no43.identity['serial_prefix']}-0002"
        assert bus.transactions == before + 1  # the serial register only, no function 43
    finally:
        server.stop()


def test_the_profile_key_must_be_a_boolean(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(DEFAULT_PROFILE.read_text(encoding="utf-8").replace("device_identification = true",
                                                                      'device_identification = "yes"'))
    with pytest.raises(ProfileError, match="device_identification: must be true or false"):
        DriveProfile.load(p)


def test_shipped_real_profiles_do_not_claim_the_function():
    profiles = DEFAULT_PROFILE.parent
    for name in ("kinco_fd.toml", "delta_asda_a2.toml"):
        assert DriveProfile.load(profiles / name).protocol.device_identification is False
    assert DriveProfile.load().protocol.device_identification is True
