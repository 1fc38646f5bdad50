"""`station ui`: the terminal UI (also what `station` with no arguments starts)."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import logging
from pathlib import Path

from procedures.vocabulary import InputError

NAME = "ui"
HELP = "the terminal UI: rig status, sweeps, results, compensation, replay, diagnosis"
DESCRIPTION = (
    "Start the station's terminal UI. Without --config it runs on the simulated rig (through the "
    "real Modbus and serial protocols) at --time-scale (default 0.02: 50x faster than real time)."
)
# A simulated sweep in the UI should be watchable, not instant (0 would finish before a redraw).
DEFAULT_SIM_TIME_SCALE = 0.02


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=V.CONFIG.argtype(), help="station TOML naming the real drives and interferometer (default: simulated rig)")
    p.add_argument("--replay", type=V.SESSION.argtype(), metavar="FILE.h5", help="start on a recorded session (Replay screen)")
    p.add_argument("--time-scale", type=V.TIME_SCALE.argtype(), metavar="S",
                   help=f"simulated rig only: real seconds per simulated second (0 = no waiting; "
                        f"default {DEFAULT_SIM_TIME_SCALE:g}, or the config's [sim] time_scale)")


def run(args) -> int:
    from station.services.sweep_job import check_time_scale
    from station.services.config import load_config

    cfg = load_config(args.config)
    cfg.require_devices()
    time_scale = args.time_scale
    if time_scale is None and args.config is None:
        time_scale = DEFAULT_SIM_TIME_SCALE
    check_time_scale(time_scale)  # nan and inf too, as `station sweep` does
    if args.replay and not Path(args.replay).is_file():
        raise InputError(f"--replay {args.replay}: no such file (give a session .h5 file)")
    cfg.with_sim_memory()  # the simulated drives keep their tables where `station push/verify --sim` find them
    # Textual owns the terminal: log to a file, never to the screen.
    log_dir = Path(cfg.recordings_dir)
    log_dir.mkdir(parents=True, exist_ok=True)
    logging.basicConfig(filename=log_dir / "station-ui.log", level=logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    from station.tui.app import StationApp

    app = StationApp(cfg, time_scale=time_scale, replay=args.replay)
    app.run()
    return app.return_code or 0
