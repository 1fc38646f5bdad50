"""Fast synthetic sessions straight from the plant, without the protocol layer.

It lives in station/ (the composition root) because it joins the plant (drivers/sim) with the
session format (procedures/io/recording): drivers never import procedures.

For analysis tests, benchmarks and the diagnosis self-check, where thousands of sessions are
needed and the Modbus/serial path is already covered by the integration tests. The motion
sequence is the same bidirectional linear cycle the sweep procedure runs (with an overrun before
each reversal), so backlash, heating and pass offsets come out as they do on the rig.
"""

from __future__ import annotations

import numpy as np

from drivers.plant.leg import LegPlant, PlantConfig
from procedures.io.recording.schema import POINT_DTYPE


def synth_session(
    configs: dict[int, PlantConfig],
    targets_mm,
    cycles: int = 5,
    seed: int = 0,
    dwell_s: float = 2.0,
    velocity_mm_s: float = 10.0,
    overrun_mm: float = 2.0,
    air=(20.0, 1013.25, 45.0),
) -> np.ndarray:
    """Simulate a bidirectional sweep of each leg in `configs` (leg number -> plant config).

    Returns a POINT_DTYPE array: one row per point, runs numbered per leg (odd runs upward,
    even runs downward), `error_um` = measured - target, `time_s` since the leg's start.
    """
    targets = np.sort(np.asarray(targets_mm, dtype=float))
    rows = []
    index = 0
    for leg in sorted(configs):
        plant = LegPlant(configs[leg], seed=seed * 1000 + leg)
        t = 0.0
        # approach the first target from below, as the sweep procedure does
        start = targets[0] - overrun_mm
        t += abs(start - plant.x_mm) / velocity_mm_s
        plant.move(start, t)
        run = 0
        for _cycle in range(cycles):
            for direction, seq in ((1, targets), (-1, targets[::-1])):
                run += 1
                for target in seq:
                    t += abs(target - plant.x_mm) / velocity_mm_s
                    plant.move(float(target), t)
                    t += dwell_s
                    measured = plant.measured_position_mm(t)
                    rows.append(
                        (
                            index, leg, run, direction, target, target, target, measured,
                            (measured - target) * 1000.0, t, air[0], air[1], air[2],
                            plant.material_temp_c(t), plant.load_n, 90.0, 0, float("nan"),  # speed: read at rest
                        )
                    )
                    index += 1
                # overrun beyond the end before reversing
                end = seq[-1] + direction * overrun_mm
                t += abs(end - plant.x_mm) / velocity_mm_s
                plant.move(end, t)
    return np.array(rows, dtype=POINT_DTYPE)
