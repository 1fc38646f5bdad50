"""Bench: station overhead per measured point on the simulated rig at time scale 0.

Per point: move (Modbus TCP on 127.0.0.1) + settle (virtual) + interferometer read (serial pty),
through the real protocol clients, with HDF5 recording. Prints the median wall time per point,
the Modbus transactions per point, and the floor measured in the same run against the same
simulated drive: a bare pymodbus round trip (a plain ModbusTcpClient reading the status block,
no station code) and the ratio of the station's cost per point to it (goal <= 2).

Targets (issue 2 and 3): <= 2 ms and <= 3 Modbus transactions per point; a full six-leg,
361-target, six-cycle sweep (25 992 points) <= 2 ms per point including recording, file <= 10 MB.

    .venv/bin/python bench/bench_point_overhead.py [--full]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pymodbus.client import ModbusTcpClient  # noqa: E402

from procedures.engine import events as ev  # noqa: E402
from procedures.acquisition.plans import SweepPlan, paper_plan  # noqa: E402
from procedures.engine.runner import CallbackSink  # noqa: E402
from station.services.config import StationConfig  # noqa: E402
from station.services.jobs import run_sweep  # noqa: E402
from station.services.wiring import open_rig  # noqa: E402


def modbus_transactions(rig) -> int:
    return next(iter(rig.axes.values())).bus.transactions


def bare_round_trips_ms(rig, n: int = 1000) -> tuple[float, float, float]:
    """Medians (ms) of the floor, without station code, on the rig's own simulated devices: a bare
    pymodbus read of the status block and a bare pymodbus function-23 move (the request a station
    move sends), each on its own connection, and a bare position exchange on the interferometer's
    pty (pyserial write + read of the reply line, no parsing)."""
    host, port = rig.sim.drive_url.removeprefix("tcp://").rsplit(":", 1)
    prof = rig.profile
    address, count, _ = prof.runs(prof.blocks["status"].names)[0]
    block = prof.blocks["move_command"]
    target = prof.registers["target_position"]
    cw = rig.axes[1]._move_cw  # the controlword of a move, as the station writes it

    def move_words(target_mm: float) -> list[int]:
        words = [0] * block.words
        words[prof.address("controlword") - block.start] = cw
        enc = target.encode(target_mm)
        words[target.address - block.start : target.address - block.start + len(enc)] = enc
        return words

    client = ModbusTcpClient(host, port=int(port))
    client.connect()
    read_t, move_t, laser_t = [], [], []
    try:
        for i in range(n):
            t0 = time.perf_counter()
            rsp = client.read_holding_registers(address, count=count, device_id=1)
            t1 = time.perf_counter()
            assert not rsp.isError()
            rsp = client.readwrite_registers(read_address=address, read_count=count, write_address=block.start,
                                             values=move_words(-50.0 + (i % 50) * 2.0), device_id=1)
            t2 = time.perf_counter()
            assert not rsp.isError()
            read_t.append(t1 - t0)
            move_t.append(t2 - t1)
        port = rig.laser._serial  # the station client's open port, used raw
        for _ in range(n):
            t0 = time.perf_counter()
            port.write(b"POS? 1\n")
            line = b""
            while not line.endswith(b"\r\n"):
                line += port.read(port.in_waiting or 1)
            laser_t.append(time.perf_counter() - t0)
    finally:
        client.close()
    ms = lambda xs: statistics.median(xs) * 1000.0  # noqa: E731
    return ms(read_t), ms(move_t), ms(laser_t)


def per_point_times(rig, plan: SweepPlan, out: Path) -> tuple[list[float], int, int]:
    stamps: list[float] = []
    sink = CallbackSink(lambda e: stamps.append(time.perf_counter()) if isinstance(e, ev.PointMeasured) else None)
    tx0 = modbus_transactions(rig)
    result = run_sweep(rig, plan, out, StationConfig(), sinks=[sink])
    assert result.outcome == "completed", result.reason
    return [b - a for a, b in zip(stamps, stamps[1:])], modbus_transactions(rig) - tx0, result.points


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--full", action="store_true", help="also the 25 992-point six-leg paper sweep")
    args = ap.parse_args()
    cfg = StationConfig()
    with tempfile.TemporaryDirectory() as tmp, open_rig(cfg, legs=(1, 2, 3, 4, 5, 6), time_scale=0.0) as rig:
        plan = SweepPlan("bench", tuple(float(x) for x in range(-90, 91, 2)), cycles=3, legs=(1,), dwell_s=1.0)
        rig.axes[1].enable()
        before = bare_round_trips_ms(rig)
        dts, tx, n = per_point_times(rig, plan, Path(tmp) / "one.h5")
        # before and after the sweep, the lower of each (the machine's load varies)
        bare, bare_move, bare_laser = (min(a, b) for a, b in zip(before, bare_round_trips_ms(rig)))
        med = statistics.median(dts) * 1000
        p95 = sorted(dts)[int(0.95 * len(dts))] * 1000
        print(f"one leg, {n} points, time scale 0, Modbus TCP loopback + serial pty + HDF5 recording:")
        print(f"  median wall time per point  {med:7.3f} ms   (target <= 2 ms)   p95 {p95:.3f} ms")
        print(f"  Modbus transactions/point   {tx / n:7.2f}      (target <= 3; includes per-pass approach moves)")
        floor = bare_move + bare_laser
        print(f"  bare pymodbus round trip    {bare:7.3f} ms   (same run, same simulated drive, status block read)")
        print(f"  ratio per point / bare      {med / bare:7.2f}      (goal <= 2)")
        print(f"  bare point floor            {floor:7.3f} ms   (bare function-23 move {bare_move:.3f} ms + bare "
              f"pty position exchange {bare_laser:.3f} ms)")
        print(f"  ratio per point / floor     {med / floor:7.2f}")
        if args.full:
            plan = paper_plan()
            out = Path(tmp) / "full.h5"
            t0 = time.perf_counter()
            dts, tx, n = per_point_times(rig, plan, out)
            wall = time.perf_counter() - t0
            size_mb = out.stat().st_size / 1e6
            print(f"six legs x 361 targets x 6 cycles = {n} points:")
            print(f"  wall {wall:.1f} s = {wall / n * 1000:.3f} ms per point (target <= 2 ms); median {statistics.median(dts)*1000:.3f} ms")
            print(f"  file size {size_mb:.2f} MB (target <= 10 MB); Modbus transactions/point {tx / n:.2f}")


if __name__ == "__main__":
    main()
