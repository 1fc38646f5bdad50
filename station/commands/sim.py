"""`station sim`: start the simulated rig standalone and print where to reach it."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import signal
import threading
from pathlib import Path


NAME = "sim"
HELP = "start the simulated rig (Modbus drives + serial interferometer) and print where to reach it"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", type=V.PORT_OR_ANY.argtype(), default=5020, help="Modbus TCP port on 127.0.0.1 (default 5020; 0 = any free)")
    p.add_argument("--rtu", action="store_true", help="also serve Modbus RTU on a pseudo-terminal")
    p.add_argument("--time-scale", type=V.TIME_SCALE.argtype(), default=1.0, help="real seconds per simulated second (default 1)")
    p.add_argument("--seed", type=V.SEED.argtype(), default=0, help="plant seed")
    p.add_argument("--nv", type=V.LOG_FILE.argtype(), metavar="FILE", help="file for the drives' table memory (EEPROM)")
    p.add_argument("--interferometer-protocol", choices=("station", "linef1"), default="station",
                   help="the simulated laser's protocol: the station's own (default) or linef1, a µLine-F1 / "
                        "HPI-3D streaming raw distance at 25 Hz (docs/interferometer-protocol.md)")


def run(args) -> int:
    if args.interferometer_protocol == "linef1" and not args.time_scale > 0:
        # standalone, nothing else moves the rig's clock: a stream at time scale 0 would never come
        print(f"station sim: error: --time-scale {args.time_scale:g} with --interferometer-protocol linef1: a "
              "streaming laser needs a running clock; give a time scale > 0 (1 = real time)")
        return 2
    from station.services.config import SimConfig
    from station.services.wiring import start_sim_rig

    sim_cfg = SimConfig(seed=args.seed)  # the station's simulated legs: a real leg's jerk limit
    try:
        rig = start_sim_rig(sim_cfg, args.time_scale, args.port, args.rtu, Path(args.nv) if args.nv else None,
                            laser_protocol=args.interferometer_protocol)
    except OSError as exc:
        print(f"station sim: error: cannot listen on 127.0.0.1:{args.port} ({exc.strerror}); try --port 0")
        return 2
    prof = rig.profile
    print("simulated rig running (Ctrl-C to stop)")
    print(f"  drives (Modbus TCP): {rig.drive_url}   unit ids 1-6 = legs 1-6")
    if rig.rtu_port:
        print(f"  drives (Modbus RTU): {rig.rtu_port}")
    if args.interferometer_protocol == "linef1":
        print(f"  interferometer (serial, µLine-F1 protocol, 3000000 baud): {rig.laser_port}")
    else:
        print(f"  interferometer (serial): {rig.laser_port}")
    print(f"  time scale: {args.time_scale:g} real s per simulated s; seed {args.seed}; "
          f"jerk limit {sim_cfg.jerk_mm_s3:g} mm/s^3")
    addr = prof.address("position_actual") if hasattr(prof, "address") else None
    if addr is not None:
        print(f"  e.g.  mbpoll -m tcp -p {rig.drive_url.rsplit(':', 1)[1]} -a 3 -t 4:int -B -0 -r {addr} -c 1 -1 127.0.0.1")
    print(flush=True)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        stop.wait()
    except KeyboardInterrupt:
        pass
    finally:
        rig.stop()
    return 0
