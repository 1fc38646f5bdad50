"""The client keeps a drive profile's line rules, counted at the simulated drive (a real Modbus
server on 127.0.0.1 / a pty): no request longer than the profile allows, the silence between
frames kept; and the simulated drive refuses what the real drive would (exception 03 or no
reply for a request too long, no reply inside the frame gap). mbpoll reads the Kinco-mapped
statusword at 0x3200."""

from __future__ import annotations

import subprocess
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

from drivers.clock import VirtualClock
from drivers.errors import CommTimeout
from drivers.interfaces import TableBank
from drivers.modbus.client import ModbusBus, RequestRefused, connect_axes
from drivers.modbus.profile import DEFAULT_PROFILE, DriveProfile, ProfileError
from drivers.sim.drive_server import SimDriveServer
from drivers.plant.leg import LegPlant, default_leg_configs
from tests.tooling import require_tool

PROFILES_DIR = DEFAULT_PROFILE.parent


def _tight_profile(tmp_path: Path, gap_ms: float = 5.0, oversize: str = "exception", unit_ids: str = '"leg"') -> DriveProfile:
    """The built-in profile on a drive that accepts 8-word reads and 3-word writes, needs
    `gap_ms` of silence, latches set-points on the rising edge and wants target then controlword."""
    text = DEFAULT_PROFILE.read_text()
    start, end = text.index("[protocol]"), text.index("[limits]")
    proto = (f"[protocol]\nmax_read_words = 8\nmax_write_words = 3\nmin_frame_gap_ms = {gap_ms}\n"
             f"move_write = \"target_then_controlword\"\nset_point_latch = \"edge\"\n"
             f"oversize_reply = \"{oversize}\"\nunit_ids = {unit_ids}\n\n")
    p = tmp_path / "tight.toml"
    p.write_text(text[:start] + proto + text[end:])
    return DriveProfile.load(p)


@contextmanager
def _server(profile: DriveProfile, legs: int = 1):
    """A simulated drive server for `profile` on 127.0.0.1; yields (server, port)."""
    plants = {i + 1: LegPlant(c, seed=i + 1) for i, c in enumerate(default_leg_configs(0, legs))}
    server = SimDriveServer(plants, VirtualClock(0.0), profile, lock=threading.RLock())
    try:
        yield server, server.start_tcp()
    finally:
        server.stop()


@pytest.fixture
def profile(tmp_path) -> DriveProfile:  # overrides tests/drivers/conftest.py: sim_drives serves it
    return _tight_profile(tmp_path)


def test_no_frame_longer_than_the_profile_allows_and_the_gap_is_kept(sim_drives, profile):
    sd = sim_drives()
    ax = sd.axis(2)
    assert ax.identity().startswith("StationSim")
    ax.check_map_version()
    ax.enable()
    for t in (10.0, -20.5, 3.25):
        st = ax.move_to(t)
        assert st.target_reached and abs(st.position_mm - t) < 1e-6
    assert ax.move_to(7.5, velocity_mm_s=5.0).target_reached
    table = TableBank(-90.0, 2.5, tuple(0.5 * i for i in range(73)), tuple(-0.25 * i for i in range(73)))
    other = 1 - ax.active_bank()
    ax.write_table(other, table)  # 2 x 73 entries + header, in writes of at most 3 words
    back = ax.read_table(other)  # ... and reads of at most 8
    assert back.error_fwd_um == pytest.approx(table.error_fwd_um, abs=0.006)
    assert back.error_rev_um == pytest.approx(table.error_rev_um, abs=0.006)
    ax.activate_table(other)
    f = sd.server.frame_stats()
    assert f.requests > 100  # the table alone: 2 x 25 writes of 3 entries, 2 x 10 reads of 8, header
    assert f.longest_read_words == 8 and f.longest_write_words == 3, f
    assert f.oversize == 0 and f.gap_violations == 0, f
    assert f.shortest_gap_s >= 0.005, f"{f.shortest_gap_s * 1000:.3f} ms between frames, the profile needs 5 ms"


def test_target_then_controlword_and_edge_latch(sim_drives, profile):
    sd = sim_drives()
    bus = sd.bus()
    sent = []
    bus.on_request = lambda kind, unit, address, count: sent.append((kind, address, count))
    ax = sd.axis(1, bus=bus)
    ax.enable()
    ax.limits()
    sent.clear()
    ax.move_to(12.0)
    cw, target = profile.address("controlword"), profile.address("target_position")
    # the target first (2 words), then the controlword with new set-point, then the bit cleared
    assert sent[:3] == [("write", target, 2), ("write", cw, 1), ("write", cw, 1)]
    # the drive latched the set-point once: a second identical controlword write (level) does not move it
    assert ax.status().position_mm == pytest.approx(12.0, abs=1e-6)
    bus.write(1, target, profile.registers["target_position"].encode(30.0))
    bus.write(1, cw, [profile.commands["enable_operation"]])  # no rising edge: nothing happens
    assert ax.status().position_mm == pytest.approx(12.0, abs=1e-6)


def test_a_request_longer_than_allowed_is_refused_with_exception_03(sim_drives, profile):
    sd = sim_drives()
    bus = sd.bus()
    with pytest.raises(RequestRefused) as info:
        bus.read(1, profile.address("statusword"), 10)  # 10 > 8: Modbus allows it, this drive does not
    assert info.value.exception_code == 3
    with pytest.raises(RequestRefused):
        bus.write(1, profile.address("controlword"), [0, 0, 0, 0])
    f = sd.server.frame_stats()
    assert f.oversize == 2 and f.longest_read_words == 10


def test_a_drive_that_ignores_long_requests_does_not_answer(tmp_path):
    prof = _tight_profile(tmp_path, gap_ms=0.0, oversize="silence")
    with _server(prof) as (server, port):
        bus = ModbusBus.from_url(f"tcp://127.0.0.1:{port}", timeout_s=0.3, retries=0)
        try:
            assert len(bus.read(1, prof.address("statusword"), 8)) == 8
            with pytest.raises(CommTimeout):
                bus.read(1, prof.address("statusword"), 9)
            assert server.frame_stats().oversize == 1
        finally:
            bus.close()


def test_frames_inside_the_gap_get_no_answer(tmp_path):
    """A client that does not keep the drive's silence is not answered (as on a real RTU line,
    where its frame would run into the previous one); the station's client keeps it."""
    prof = _tight_profile(tmp_path, gap_ms=400.0)
    with _server(prof) as (server, port):
        rude = ModbusBus.from_url(f"tcp://127.0.0.1:{port}", timeout_s=0.2, retries=0)  # keeps no gap
        polite = ModbusBus.from_url(f"tcp://127.0.0.1:{port}", timeout_s=1.0, retries=0)
        try:
            rude.read(1, prof.address("statusword"), 1)
            with pytest.raises(CommTimeout):
                rude.read(1, prof.address("statusword"), 1)  # sent at once: inside the 400 ms
            assert server.frame_stats().gap_violations == 1
            rude.close()
            polite.require_gap(prof.protocol.min_frame_gap_ms / 1000.0)
            time.sleep(0.4)  # the rude client's last frame was a frame too
            t0 = time.monotonic()
            for _ in range(3):
                polite.read(1, prof.address("statusword"), 1)
            assert time.monotonic() - t0 >= 0.8  # two gaps of 400 ms waited between the three
            f = server.frame_stats()
            assert f.gap_violations == 1, f
        finally:
            rude.close()
            polite.close()


def test_unit_ids_from_the_profile(tmp_path):
    prof = _tight_profile(tmp_path, gap_ms=0.0, unit_ids="{ 1 = 11, 2 = 12 }")
    assert (prof.protocol.unit_id(1), prof.protocol.unit_id(2)) == (11, 12)
    with _server(prof, legs=2) as (server, port):
        axes = connect_axes(f"tcp://127.0.0.1:{port}", (1, 2), prof, timeout_s=0.5, retries=0)
        try:
            assert [a.unit for a in axes.values()] == [11, 12]
            axes[2].enable()
            axes[2].move_to(4.0)
            assert server.state(2) == "operation_enabled" and server.state(1) == "switch_on_disabled"
            bus = axes[1].bus
            with pytest.raises(CommTimeout):
                bus.read(2, prof.address("statusword"), 1)  # unit 2 is nobody on this line
        finally:
            for a in axes.values():
                a.close()


def test_a_unit_id_table_must_name_every_leg(tmp_path):
    prof = _tight_profile(tmp_path, gap_ms=0.0, unit_ids="{ 1 = 11 }")
    with pytest.raises(ProfileError, match="unit_ids has no unit id for leg 3"):
        prof.protocol.unit_id(3)
    with pytest.raises(ProfileError, match="two legs share a unit id"):
        _tight_profile(tmp_path, gap_ms=0.0, unit_ids="{ 1 = 11, 2 = 11 }")


def test_mbpoll_reads_the_kinco_statusword_at_0x3200():
    """mbpoll (libmodbus) reads the simulated Kinco drive where the Kinco manual puts 6041h
    (0x3200), and its position actual (6063h at 0x3700, low word first: mbpoll's default)."""
    mbpoll = require_tool("mbpoll")
    prof = DriveProfile.load(PROFILES_DIR / "kinco_fd.toml")
    assert prof.address("statusword") == 0x3200 and prof.address("controlword") == 0x3100
    with _server(prof, legs=4) as (server, port):
        axes = connect_axes(f"tcp://127.0.0.1:{port}", (4,), prof, timeout_s=1.0)
        ax = axes[4]
        try:
            ax.enable()
            st = ax.move_to(-12.5)
            sw = prof.registers["statusword"].decode(ax.bus.read(4, 0x3200, 1))
        finally:
            ax.close()

        def poll(address: int, typ: str) -> int:
            out = subprocess.run([mbpoll, "-m", "tcp", "-p", str(port), "-a", "4", "-r", str(address), "-t", typ,
                                  "-c", "1", "-1", "-0", "127.0.0.1"], capture_output=True, text=True, timeout=10)
            assert out.returncode == 0, out.stdout + out.stderr
            line = next(ln for ln in out.stdout.splitlines() if ln.startswith(f"[{address}]:"))
            return int(line.split(":", 1)[1].split()[0])

        assert poll(0x3200, "4") == sw
        assert prof.state_of(sw) == "operation_enabled" and prof.sw_bit(sw, "target_reached")
        counts = poll(0x3700, "4:int")
        assert counts == round(-12.5 * prof.scaling["position_counts_per_mm"]) == -163840
        assert counts / prof.scaling["position_counts_per_mm"] == pytest.approx(st.position_mm, abs=1e-9)


def test_mbpoll_reads_the_delta_parameters_and_the_gap_is_kept():
    """mbpoll reads the simulated Delta drive's P0-46 (servo output status, 0x005C) and P0-09
    (feedback position in PUU, 0x0012, low word first), after the station's client drove it
    keeping the 10 ms silence and 10-word reads of the Delta manual."""
    mbpoll = require_tool("mbpoll")
    prof = DriveProfile.load(PROFILES_DIR / "delta_asda_a2.toml")
    assert (prof.protocol.max_read_words, prof.protocol.min_frame_gap_ms) == (10, 10.0)
    with _server(prof, legs=2) as (server, port):
        axes = connect_axes(f"tcp://127.0.0.1:{port}", (2,), prof, timeout_s=1.0)
        ax = axes[2]
        try:
            ax.enable()
            st = ax.move_to(31.25)
            ax.move_to(-4.5)
            st = ax.move_to(31.25)
        finally:
            ax.close()
        f = server.frame_stats()
        assert f.oversize == 0 and f.gap_violations == 0 and f.shortest_gap_s >= 0.010, f
        assert f.longest_read_words <= 10 and f.longest_write_words <= 2, f
        time.sleep(0.02)  # mbpoll keeps no gap of its own before its first frame

        def poll(address: int, typ: str) -> int:
            out = subprocess.run([mbpoll, "-m", "tcp", "-p", str(port), "-a", "2", "-r", str(address), "-t", typ,
                                  "-c", "1", "-1", "-0", "127.0.0.1"], capture_output=True, text=True, timeout=10)
            assert out.returncode == 0, out.stdout + out.stderr
            line = next(ln for ln in out.stdout.splitlines() if ln.startswith(f"[{address}]:"))
            return int(line.split(":", 1)[1].split()[0])

        status = poll(0x005C, "4")  # the low word of P0-46 holds its bits 0..15
        assert status & 0b0101_0011 == 0b0001_0011  # SRDY, SON, TPOS set; ALRM clear
        time.sleep(0.02)
        assert poll(0x0012, "4:int") == 31250 == round(st.position_mm * 1000)  # PUU = 1 um
