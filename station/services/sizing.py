"""Sizes of the work a size-driven option asks for, estimated before the work starts (issue 31,
item 3), as procedures/acquisition/plan_size.py sizes a sweep plan: the estimate is printed, and
refused beyond a limit with the figures and the largest value that fits.

The per-item figures were measured on the bench PC's class of machine (2 cores) with the sample
recording (`station platform recordings/calibration-6legs.h5 --poses N`, /usr/bin/time): 2 000
poses 109 MB, 20 000 poses 187 MB, 100 000 poses 543 MB and 8.9 s; a diagnosis self-check about
1 s per session. They are upper-side estimates, not promises; tests/station/test_cli_sizes.py
checks that the estimate is not below what a run takes.
"""

from __future__ import annotations

from dataclasses import dataclass

from procedures.vocabulary import InputError

PLATFORM_BASE_BYTES = 150e6
"""The interpreter, numpy, matplotlib and the recording: what a platform run takes at any size."""
PLATFORM_BYTES_PER_POSE = 5_000.0
"""Per pose: its six leg lengths, errors and both poses for two measurements, kept for the
histograms and the report (measured 4.5 kB)."""
PLATFORM_S_PER_POSE = 1.2e-4
"""Inverse and forward kinematics of one pose, twice (measured 0.08 ms on a loaded machine)."""
MAX_MEMORY_BYTES = 2e9
"""The most memory a command may plan to take: a bench PC has 4..8 GB and runs the UI beside it."""
SELFCHECK_S_PER_SESSION = 1.5
"""A diagnosis self-check session: simulate, fit the twin, diagnose (measured about 1 s)."""


def _mb(n: float) -> str:
    return f"{n / 1e9:.1f} GB" if n >= 1e9 else f"{n / 1e6:.0f} MB"


def _time(s: float) -> str:
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"


@dataclass(frozen=True)
class Estimate:
    """What a run will take: `memory_bytes` at its peak and `seconds` of computation."""

    what: str
    memory_bytes: float
    seconds: float

    def describe(self) -> str:
        return f"{self.what}: about {_mb(self.memory_bytes)} of memory and {_time(self.seconds)}"


def platform_estimate(poses: int) -> Estimate:
    return Estimate(f"{poses} poses", PLATFORM_BASE_BYTES + PLATFORM_BYTES_PER_POSE * poses,
                    2.0 + PLATFORM_S_PER_POSE * poses)


def check_platform_poses(poses: int, max_bytes: float = MAX_MEMORY_BYTES) -> Estimate:
    """The estimate of `station platform --poses N` (the UI's Platform page too); InputError when
    it needs more than `max_bytes`, naming the figures and the most poses that fit."""
    est = platform_estimate(poses)
    if est.memory_bytes > max_bytes:
        most = int((max_bytes - PLATFORM_BASE_BYTES) // PLATFORM_BYTES_PER_POSE)
        raise InputError(f"--poses {poses}: {est.describe()}, more than the {_mb(max_bytes)} a run may take; "
                         f"give --poses {most} or fewer (2000, the default, gives the paper's Table 2); "
                         "nothing was written")
    return est


def selfcheck_estimate(sessions: int) -> Estimate:
    return Estimate(f"{sessions} simulated sessions", 200e6, 2.0 + SELFCHECK_S_PER_SESSION * sessions)
