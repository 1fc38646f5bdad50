"""How fast and in how much memory `station sweep` refuses a plan that cannot finish (issue 22
item 3: under 1 s, RSS under 200 MB, before connecting). Runs the real command in a child
process and prints its wall time and peak RSS.

    .venv/bin/python bench/bench_plan_refusal.py [--step 0.0001]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--step", default="0.0001")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "huge.h5"
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "station.cli", "sweep", "--sim", "--step", args.step,
                               "--out", str(out)], cwd=REPO, capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(REPO)})
        wall = time.perf_counter() - t0
        rss_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        print(f"exit {proc.returncode}  {wall:.2f} s wall (process start included)  peak RSS {rss_mb:.0f} MB  "
              f"file written: {out.exists()}")
        print(proc.stderr.strip())


if __name__ == "__main__":
    main()
