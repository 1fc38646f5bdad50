"""Bench: diagnosis of a six-leg, 361-target, six-cycle session (the paper's sweep).

Target: <= 1 s of CPU time per diagnosis (default twin fitted on the recording). Also timed: the same
session against the simulated plant as twin (where scale and cyclic are tried too).
Prints figures; not a timed test.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivers.plant.leg import default_leg_configs  # noqa: E402
from procedures.synthetic import synth_session  # noqa: E402
from procedures.diagnosis import diagnose  # noqa: E402
from procedures.diagnosis.twin import plant_twin  # noqa: E402

TARGET_S = 1.0  # CPU seconds (issue 25: at most 1 s with the variants tried)


def main() -> int:
    cfgs = {i + 1: c for i, c in enumerate(default_leg_configs(seed=1))}
    targets = np.linspace(-90.0, 90.0, 361)
    t0 = time.perf_counter()
    points = synth_session(cfgs, targets, cycles=6, seed=1)
    print(f"session: {len(cfgs)} legs x {targets.size} targets x 6 cycles = {points.size} points "
          f"(synthesised in {time.perf_counter() - t0:.2f} s)")
    worst = 0.0
    for label, twin in (("twin fitted on the recording", None),
                        ("twin = simulated plant (position terms)", plant_twin(cfgs, "plant"))):
        times, cpu = [], []
        for _ in range(3):
            t0, c0 = time.perf_counter(), time.process_time()
            report = diagnose(points, twin)
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        named = ", ".join(f"{f['effect']}@{f['leg']}" for f in report["findings"]) or "none"
        # CPU time too: on a shared machine the wall clock also measures the other processes
        print(f"{label}: wall best {min(times):.2f} s, median {np.median(times):.2f} s; CPU best {min(cpu):.2f} s "
              f"(target <= {TARGET_S} s); named: {named}")
        worst = max(worst, min(cpu))
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    print("OK" if worst <= TARGET_S else "SLOWER THAN TARGET")
    return 0


if __name__ == "__main__":
    sys.exit(main())
