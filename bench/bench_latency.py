"""The transports' latency apart from the leg's lag, on the simulated rig, for both lasers
(procedures/acquisition/latency.py; docs/interferometer-protocol.md, "Measuring the latency").

On a fresh one-leg rig of plant seed `--seed` (time scale 0, the leg with a real drive's jerk
limit), with known delays given to the simulated transports:

- the station's own laser (latched at the drive's compare pulse): the Modbus poll's round trip
  at rest, and the leg's speed lag per direction, its own (no transport in a latched reading);
- the µLine-F1 (streamed, aligned on the clock): the poll's round trip at rest and along the
  traced passes, the stream's arrival jitter against its frame grid, and the speed lag per
  direction: the leg's plus the delay of the laser's stamps behind the drive's;
- the µLine-F1 again with the reflector on the drive's nut (the leg's lag taken out of the
  plant: no leg between the encoder and the beam): its speed lag is the delay alone;
- the delay: the second lag less the first, per direction, and the third, against what was
  injected (the laser's latency, less half the Modbus delays' asymmetry: the drive's stamps are
  the middle of each request).

Run: .venv/bin/python bench/bench_latency.py [--laser-latency-ms 3] [--laser-jitter-ms 2]
     [--drive-delay-ms 0.6 0.4] [--drive-jitter-ms 0.2] [--seed 0]
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivers.interferometer.client import SerialInterferometer  # noqa: E402
from drivers.linef1.client import LineF1Interferometer  # noqa: E402
from drivers.modbus.client import connect_axes  # noqa: E402
from drivers.plant.leg import default_leg_configs  # noqa: E402
from drivers.sim.rig import SimRig  # noqa: E402
from procedures.acquisition.latency import LatencyReport, measure_latency, transport_delay  # noqa: E402
from procedures.engine.control import RunControl  # noqa: E402

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def measure(protocol: str, seed: int, laser_latency_s: float = 0.0, laser_jitter_s: float = 0.0,
            drive_delay_s: tuple[float, float] = (0.0, 0.0), drive_jitter_s: float = 0.0, on_nut: bool = False,
            **kwargs) -> LatencyReport:
    """`measure_latency` on leg 1 of a fresh simulated rig with `protocol`'s laser; `on_nut`: the
    reflector on the drive's nut (no leg between it and the encoder: no lag of the leg's)."""
    cfgs = [c.with_leg_motion() for c in default_leg_configs(seed, 1)]
    if on_nut:
        cfgs = [replace(c, dynamic_lag_up_s=0.0, dynamic_lag_down_s=0.0) for c in cfgs]
    streamed = protocol == "linef1"
    with SimRig(time_scale=0.0, seed=seed, legs=1, configs=cfgs, laser_protocol=protocol,
                laser_latency_s=laser_latency_s if streamed else 0.0, laser_jitter_s=laser_jitter_s if streamed else 0.0,
                drive_delay_s=drive_delay_s, drive_jitter_s=drive_jitter_s) as rig:
        axis = connect_axes(rig.drive_url, [1], clock=rig.clock)[1]
        laser = (LineF1Interferometer if streamed else SerialInterferometer)(rig.laser_port, clock=rig.clock)
        try:
            axis.enable()
            run = measure_latency(1, axis, laser, rig.clock, RunControl(), -60.0, 60.0, **kwargs)
            while True:
                try:
                    next(run)
                except StopIteration as stop:
                    return stop.value
        finally:
            laser.close()
            axis.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--laser-latency-ms", type=float, default=3.0)
    ap.add_argument("--laser-jitter-ms", type=float, default=2.0)
    ap.add_argument("--drive-delay-ms", type=float, nargs=2, default=(0.6, 0.4), metavar=("REQUEST", "RESPONSE"))
    ap.add_argument("--drive-jitter-ms", type=float, default=0.2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cycles", type=int, default=2)
    args = ap.parse_args(argv)
    delays = dict(drive_delay_s=tuple(d / 1000.0 for d in args.drive_delay_ms), drive_jitter_s=args.drive_jitter_ms / 1000.0)
    print(f"injected: laser latency {args.laser_latency_ms:g} ms + uniform 0..{args.laser_jitter_ms:g} ms (µLine-F1 "
          f"frames), Modbus request {args.drive_delay_ms[0]:g} ms / response {args.drive_delay_ms[1]:g} ms + uniform "
          f"0..{args.drive_jitter_ms:g} ms split between them; seed {args.seed}, cycles {args.cycles}")
    reports = {}
    for name, protocol, on_nut in (("station", "station", False), ("linef1", "linef1", False),
                                   ("linef1, reflector on the nut", "linef1", True)):
        t = time.perf_counter()
        r = reports[name] = measure(protocol, args.seed, args.laser_latency_ms / 1000.0, args.laser_jitter_ms / 1000.0,
                                    cycles=args.cycles, on_nut=on_nut, **delays)
        print(f"\n{name} laser ({r.laser}), leg {r.leg}  [{time.perf_counter() - t:.1f} s of real time]")
        print(f"  Modbus poll at rest      {r.poll_rest.text()}")
        if r.poll_traced is not None:
            print(f"  Modbus poll in passes    {r.poll_traced.text()}")
        if r.stream is not None:
            s = r.stream
            print(f"  stream arrival jitter    {s.jitter.text()}; {s.frames} frames over {s.span_s:.1f} s, "
                  f"{s.lost} lost, rate {s.drift_ppm:+.1f} ppm from nominal")
        else:
            print("  stream arrival jitter    none: latched at the drive's compare pulse (a wire)")
        for lag in r.lags:
            print(f"  speed lag {'up  ' if lag.direction > 0 else 'down'}           {lag.lag_ms:+.4f} ms "
                  f"(s {lag.stderr_ms:.4f} ms, {lag.passes} passes at {lag.speeds_mm_s} mm/s)")
    d = transport_delay(reports["linef1"], reports["station"])
    expected = args.laser_latency_ms - 0.5 * (args.drive_delay_ms[1] - args.drive_delay_ms[0])
    per = ", ".join(f"{'up' if k > 0 else 'down'} {v:+.4f}" for k, v in d.per_direction_ms)
    print(f"\ndelay of the µLine-F1's stamps behind the drive's polls: {d.delay_ms:+.4f} ms (s {d.stderr_ms:.4f} ms; "
          f"{per} ms; directions differ by {d.disagreement_ms:.4f} ms)")
    nut = reports["linef1, reflector on the nut"]
    print(f"the same with the reflector on the nut (no leg's lag), its speed lag: {nut.lag_ms:+.4f} ms "
          f"(up {nut.lags[0].lag_ms:+.4f}, down {nut.lags[1].lag_ms:+.4f} ms); error {nut.lag_ms - expected:+.4f} ms")
    print(f"injected: {expected:+.4f} ms (laser latency {args.laser_latency_ms:g} ms less half the Modbus asymmetry "
          f"{args.drive_delay_ms[1] - args.drive_delay_ms[0]:+g} ms); error {d.delay_ms - expected:+.4f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
