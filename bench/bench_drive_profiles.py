"""Bench: each drive profile on the simulated rig, through the real clients: line rules, and the
wire time of a stop-and-go point and an on-the-fly pass, function 23 off (before) and on where
the profile says the drive serves it (after), side by side.

Part 1, line rules (per profile): Modbus requests per move and per status read, the longest
read and write the drive saw against what the profile allows, requests longer than allowed and
requests inside the frame gap (both must be 0), the shortest silence between frames against the
profile's minimum, and the wall time per move + status on loopback at time scale 0.

Part 2, wire time: a stop-and-go sweep (`--targets` targets, 2 cycles, one leg) and, where the
profile has position-compare registers, an on-the-fly sweep (2 passes at each plan speed) run
through station.services.jobs.run_sweep on the simulated rig. The drive bus tallies the RTU frames of
every request (drivers/modbus/wire.py); the figures are per measured point (mean over the
sweep's points after the first, approach moves included) and per on-the-fly pass (mean over the
passes after the first, the capture read-out included), modelled on an RTU line at `--baud`:
11 bits per byte, 3.5 characters of silence after each frame, the profile's min_frame_gap_ms
between transactions (the drive's own reply time is not modelled). The laser line: its
exchanges and bytes, at `--laser-baud`, 10 bits per byte (8N1), no silences; before: the
capture read back one sample per exchange (`CAP?`), after: in blocks (`CAPB?`).

    .venv/bin/python bench/bench_drive_profiles.py [--moves 50] [--targets 11] [--baud 115200]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
# sessions in temporary folders, of no leg: not for the station's catalog (whose indexing thread
# would find them gone)
os.environ.setdefault("STATION_CATALOG", "off")

import logging  # noqa: E402

from drivers.clock import VirtualClock  # noqa: E402
from drivers.modbus.client import connect_axes  # noqa: E402
from drivers.modbus.profile import DEFAULT_PROFILE, DriveProfile  # noqa: E402
from drivers.modbus.wire import WireTally, rtu_ms  # noqa: E402
from drivers.sim.drive_server import SimDriveServer  # noqa: E402
from drivers.plant.leg import LegPlant, default_leg_configs  # noqa: E402
from procedures.engine import events as ev  # noqa: E402
from procedures.acquisition.plans import SweepPlan, onthefly_plan, uniform_targets  # noqa: E402
from procedures.engine.runner import CallbackSink  # noqa: E402
from station.services.config import StationConfig  # noqa: E402
from station.services.jobs import run_sweep  # noqa: E402
from station.services.wiring import open_rig  # noqa: E402

LASER_BITS_PER_BYTE = 10  # 8N1


def bench(path: Path, moves: int) -> dict:
    prof = DriveProfile.load(path)
    plants = {1: LegPlant(default_leg_configs(0, 1)[0], seed=1)}
    server = SimDriveServer(plants, VirtualClock(0.0), prof, lock=threading.RLock())
    port = server.start_tcp()
    axis = connect_axes(f"tcp://127.0.0.1:{port}", (1,), prof, timeout_s=2.0)[1]
    try:
        axis.enable()
        bus = axis.bus
        tx = bus.transactions
        axis.status()
        per_status = bus.transactions - tx
        times, per_move = [], []
        for i in range(moves):
            target = -80.0 + 160.0 * ((i * 37) % moves) / moves
            tx, t0 = bus.transactions, time.perf_counter()
            axis.move_to(target)
            times.append(time.perf_counter() - t0)
            per_move.append(bus.transactions - tx)
        f = server.frame_stats()
    finally:
        axis.close()
        server.stop()
    return {"profile": prof.name, "per_move": statistics.median(per_move), "per_status": per_status,
            "read": f"{f.longest_read_words}/{prof.protocol.max_read_words}",
            "write": f"{f.longest_write_words}/{prof.protocol.max_write_words}",
            "oversize": f.oversize, "gap_viol": f.gap_violations,
            "gap": f"{f.shortest_gap_s * 1000:.2f}/{prof.protocol.min_frame_gap_ms:g}",
            "ms_move": statistics.median(times) * 1000}


def without_function_23(path: Path, tmp: Path) -> Path | None:
    """A copy of the profile with function 23 off; None when it is off already."""
    text = path.read_text(encoding="utf-8")
    if not DriveProfile.load(path).protocol.read_write_multiple:
        return None
    out = tmp / f"{path.stem}-no-fc23.toml"
    out.write_text(text.replace("read_write_multiple = true", "read_write_multiple = false"), encoding="utf-8")
    assert not DriveProfile.load(out).protocol.read_write_multiple, f"{path}: cannot switch function 23 off"
    return out


def wire_of_sweep(profile_path: Path, plan: SweepPlan, tmp: Path, per_pass: bool,
                  block_reads: bool = True) -> tuple[WireTally, float, float, float, int]:
    """For `plan` on the simulated rig with the profile: the Modbus tally over the points (or
    passes) counted, the laser exchanges and bytes per point (or pass), the points per pass,
    and how many points (or passes) the tally covers (the first one, which carries the leg's
    preparation, is left out)."""
    cfg = StationConfig()
    cfg.drive.profile = str(profile_path)
    with open_rig(cfg, legs=plan.legs, time_scale=0.0) as rig:
        bus = rig.axes[plan.legs[0]].bus
        laser = rig.laser
        laser.capture_block = block_reads  # off: the capture read back one sample per exchange (CAP?)
        marks: list[tuple[int, WireTally, int, int]] = []  # (run, modbus, laser exchanges, laser bytes)

        def mark(e) -> None:
            if isinstance(e, ev.PointMeasured):
                marks.append((int(e.record["run"]), bus.wire.copy(), laser.transactions, laser.bytes_out + laser.bytes_in))

        out = tmp / f"{profile_path.stem}-{plan.kind}-{'blocks' if block_reads else 'single'}.h5"
        result = run_sweep(rig, plan, out, cfg, sinks=[CallbackSink(mark)])
        assert result.outcome == "completed", result.reason
    if per_pass:
        # a pass's points arrive together after it: its traffic lies between the last point of the
        # previous pass and its own last point (the first pass carries the leg's preparation)
        ends = [m for m, nxt in zip(marks, marks[1:] + [None]) if nxt is None or nxt[0] != m[0]]
        first, last, n = ends[0], ends[-1], len(ends) - 1
        points_per_pass = (len(marks) - sum(1 for m in marks if m[0] == first[0])) / n
    else:
        first, last, n = marks[0], marks[-1], len(marks) - 1
        points_per_pass = 1.0
    return last[1] - first[1], (last[2] - first[2]) / n, (last[3] - first[3]) / n, points_per_pass, n


def wire_rows(path: Path, args, tmp: Path) -> list[str]:
    prof = DriveProfile.load(path)
    off = without_function_23(path, tmp)
    gap = prof.protocol.min_frame_gap_ms
    targets = uniform_targets(-40.0, 40.0, 80.0 / (args.targets - 1))
    kinds = [("stop-and-go point", SweepPlan("bench", targets, cycles=2, legs=(1,), dwell_s=1.0), False)]
    if "compare" in prof.blocks:
        otf = onthefly_plan(legs=(1,), cycles=4, step_mm=0.5, min_mm=-40.0, max_mm=40.0)
        kinds.append(("on-the-fly pass", otf, True))
    rows = []
    for what, plan, per_pass in kinds:
        before = wire_of_sweep(off or path, plan, tmp, per_pass, block_reads=False)
        after = wire_of_sweep(path, plan, tmp, per_pass)
        b = before
        n_b, n_a = b[4], after[4]
        ms_b = rtu_ms(b[0], args.baud, gap) / n_b
        ms_a = rtu_ms(after[0], args.baud, gap) / n_a
        laser_ms_b, laser_ms = (x[2] * LASER_BITS_PER_BYTE / args.laser_baud * 1000 for x in (b, after))
        saving = f"{(1 - ms_a / ms_b) * 100:5.1f} %" if off else "  (no FC23)"
        per = f" ({after[3]:.0f} samples)" if per_pass else ""
        rows.append(
            f"  {prof.name:14} {what + per:33} {b[0].transactions / n_b:6.2f} -> {after[0].transactions / n_a:6.2f} tx "
            f"{b[0].bytes / n_b:8.1f} -> {after[0].bytes / n_a:8.1f} B {ms_b:8.2f} -> {ms_a:8.2f} ms {saving} | "
            f"laser {b[1]:6.2f} -> {after[1]:6.2f} exch {b[2]:7.1f} -> {after[2]:7.1f} B {laser_ms_b:7.2f} -> {laser_ms:7.2f} ms")
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--moves", type=int, default=50)
    ap.add_argument("--targets", type=int, default=11, help="stop-and-go targets per pass")
    ap.add_argument("--baud", type=int, default=115200, help="RTU line the Modbus figures are modelled on")
    ap.add_argument("--laser-baud", type=int, default=StationConfig().interferometer.baudrate)
    args = ap.parse_args()
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    paths = sorted(DEFAULT_PROFILE.parent.glob("*.toml"))
    print("line rules, loopback at time scale 0:")
    print(f"{'profile':16} {'req/move':>8} {'req/status':>10} {'read seen/max':>13} {'write seen/max':>14} "
          f"{'oversize':>8} {'in gap':>6} {'gap ms seen/min':>15} {'ms/move':>8}")
    for path in paths:
        r = bench(path, args.moves)
        print(f"{r['profile']:16} {r['per_move']:8g} {r['per_status']:10d} {r['read']:>13} {r['write']:>14} "
              f"{r['oversize']:8d} {r['gap_viol']:6d} {r['gap']:>15} {r['ms_move']:8.2f}")
    print(f"\nwire time, Modbus RTU modelled at {args.baud} baud (11 bits/byte, 3.5-character silences, the profile's "
          f"gap), function 23 off -> on where the profile serves it; laser line at {args.laser_baud} baud (8N1), "
          f"capture read one sample per exchange -> in blocks:")
    with tempfile.TemporaryDirectory() as tmp:
        for path in paths:
            for row in wire_rows(path, args, Path(tmp)):
                print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
