"""Bench: each drive profile's line rules on the simulated drive, through the real client.

For every profile in drivers/modbus/profiles/: Modbus requests per move and per status read,
the longest read and write the drive saw against what the profile allows, requests longer than
allowed and requests inside the frame gap (both must be 0), the shortest silence between frames
against the profile's minimum, and the wall time per move + status on loopback at time scale 0
(the frame gap dominates on a drive that needs one: Delta's 10 ms).

    .venv/bin/python bench/bench_drive_profiles.py [--moves 50]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import logging  # noqa: E402

from drivers.clock import VirtualClock  # noqa: E402
from drivers.modbus.client import connect_axes  # noqa: E402
from drivers.modbus.profile import DEFAULT_PROFILE, DriveProfile  # noqa: E402
from drivers.sim.drive_server import SimDriveServer  # noqa: E402
from drivers.sim.plant import LegPlant, default_leg_configs  # noqa: E402


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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--moves", type=int, default=50)
    args = ap.parse_args()
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    print(f"{'profile':16} {'req/move':>8} {'req/status':>10} {'read seen/max':>13} {'write seen/max':>14} "
          f"{'oversize':>8} {'in gap':>6} {'gap ms seen/min':>15} {'ms/move':>8}")
    for path in sorted(DEFAULT_PROFILE.parent.glob("*.toml")):
        r = bench(path, args.moves)
        print(f"{r['profile']:16} {r['per_move']:8g} {r['per_status']:10d} {r['read']:>13} {r['write']:>14} "
              f"{r['oversize']:8d} {r['gap_viol']:6d} {r['gap']:>15} {r['ms_move']:8.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
