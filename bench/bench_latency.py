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

On a real bench (or any configured rig): `--config C --leg N --stroke LO HI` measures that rig's
leg with its configured laser (the axis enabled for it; motion inside the soft limits only) and
prints the same figures; `--save F.json` keeps the report, `--reference F.json` prints the delay
against a report saved from the station's own (latched) laser on the same leg, or from the
streamed laser with its reflector on the drive's nut (docs/interferometer-protocol.md).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivers.interferometer.client import SerialInterferometer  # noqa: E402
from drivers.linef1.client import LineF1Interferometer  # noqa: E402
from drivers.modbus.client import connect_axes  # noqa: E402
from drivers.plant.leg import default_leg_configs  # noqa: E402
from drivers.sim.rig import SimRig  # noqa: E402
from drivers.errors import DriverError  # noqa: E402
from procedures.acquisition.latency import LatencyReport, measure_latency, transport_delay  # noqa: E402
from procedures.engine import events as ev  # noqa: E402
from procedures.engine.control import RunControl  # noqa: E402
from procedures.vocabulary import InputError  # noqa: E402

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
            return _run(measure_latency(1, axis, laser, rig.clock, RunControl(), -60.0, 60.0, **kwargs))
        finally:
            laser.close()
            axis.close()


def _run(events, say=None) -> LatencyReport:
    """Drive the procedure's generator; `say(text)` for its messages."""
    while True:
        try:
            event = next(events)
        except StopIteration as stop:
            return stop.value
        if say is not None and isinstance(event, ev.Message):
            say(event.text)


def print_report(name: str, r: LatencyReport, extra: str = "") -> None:
    print(f"\n{name} laser ({r.laser}), leg {r.leg}{extra}")
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


def print_delay(d) -> None:
    per = ", ".join(f"{'up' if k > 0 else 'down'} {v:+.4f}" for k, v in d.per_direction_ms)
    print(f"\ndelay of the streamed laser's stamps behind the drive's polls: {d.delay_ms:+.4f} ms "
          f"(s {d.stderr_ms:.4f} ms; {per} ms; directions differ by {d.disagreement_ms:.4f} ms)")


def on_config(args) -> int:
    """Measure the configured rig's leg (module docstring)."""
    from station.services.config import load_config
    from station.services.wiring import open_rig

    reference = None
    if args.reference:
        try:
            data = json.loads(Path(args.reference).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"{args.reference}: cannot read the reference report ({exc}); save one with --save") from None
        reference = LatencyReport.from_dict(data, args.reference)
    cfg = load_config(args.config)
    with open_rig(cfg, legs=(args.leg,)) as rig:
        axis = rig.axes[args.leg]
        axis.enable()
        report = _run(measure_latency(args.leg, axis, rig.laser, rig.clock, RunControl(), args.stroke[0],
                                      args.stroke[1], speeds_mm_s=tuple(args.speeds), cycles=args.cycles),
                      say=lambda text: print(text, flush=True))
    print_report(cfg.interferometer.protocol, report, f" on {rig.description}")
    if args.save:
        Path(args.save).write_text(json.dumps(asdict(report), indent=2), encoding="utf-8")
        print(f"saved to {args.save}")
    if reference is not None:
        print_delay(transport_delay(report, reference))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--laser-latency-ms", type=float, default=3.0)
    ap.add_argument("--laser-jitter-ms", type=float, default=2.0)
    ap.add_argument("--drive-delay-ms", type=float, nargs=2, default=(0.6, 0.4), metavar=("REQUEST", "RESPONSE"))
    ap.add_argument("--drive-jitter-ms", type=float, default=0.2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cycles", type=int, default=2)
    ap.add_argument("--config", metavar="C", help="measure this station TOML's rig instead (a real bench)")
    ap.add_argument("--leg", type=int, default=1, help="with --config: the leg (default 1)")
    ap.add_argument("--stroke", type=float, nargs=2, default=(-60.0, 60.0), metavar=("LO", "HI"),
                    help="with --config: the travel, mm, inside the soft limits (default -60 60)")
    ap.add_argument("--speeds", type=float, nargs="+", default=(10.0, 20.0), metavar="MM_S",
                    help="with --config: the pass speeds, two or more (default 10 20)")
    ap.add_argument("--save", metavar="F.json", help="with --config: write the report")
    ap.add_argument("--reference", metavar="F.json", help="with --config: print the delay against this saved report")
    args = ap.parse_args(argv)
    if args.config:
        try:
            return on_config(args)
        except (InputError, DriverError) as exc:  # one line, no traceback
            print(f"bench_latency: {exc}", file=sys.stderr)
            return 2
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
        print_report(name, r, f"  [{time.perf_counter() - t:.1f} s of real time]")
    d = transport_delay(reports["linef1"], reports["station"])
    expected = args.laser_latency_ms - 0.5 * (args.drive_delay_ms[1] - args.drive_delay_ms[0])
    print_delay(d)
    nut = reports["linef1, reflector on the nut"]
    print(f"the same with the reflector on the nut (no leg's lag), its speed lag: {nut.lag_ms:+.4f} ms "
          f"(up {nut.lags[0].lag_ms:+.4f}, down {nut.lags[1].lag_ms:+.4f} ms); error {nut.lag_ms - expected:+.4f} ms")
    print(f"injected: {expected:+.4f} ms (laser latency {args.laser_latency_ms:g} ms less half the Modbus asymmetry "
          f"{args.drive_delay_ms[1] - args.drive_delay_ms[0]:+g} ms); error {d.delay_ms - expected:+.4f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
