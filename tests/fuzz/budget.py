"""Fuzzing budget (hypothesis profiles) and the count of inputs per reader.

Profiles:
- "ci" (the default): a fixed budget, small enough that the whole of tests/fuzz runs in well
  under a minute on two cores; `derandomize=True`, so CI feeds the same inputs every time and a
  failure reproduces. New inputs come from the long profile.
- "long": `HYPOTHESIS_PROFILE=long .venv/bin/python -m pytest -p no:cacheprovider tests/fuzz`:
  50 times the inputs, random each run (tens of minutes); run it after changing a reader.

Every test calls `fed(reader, refused)` once per input; tests/fuzz/conftest.py prints how many
inputs each reader got and how many it refused with its own error (docs/reliability.md).
"""

from __future__ import annotations

import os
from collections import Counter

from hypothesis import HealthCheck, settings

_SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much,
            HealthCheck.function_scoped_fixture]

CI_EXAMPLES = 60
settings.register_profile("ci", max_examples=CI_EXAMPLES, deadline=5000, derandomize=True, database=None,
                          suppress_health_check=_SLOW_OK, print_blob=True)
settings.register_profile("long", max_examples=50 * CI_EXAMPLES, deadline=20000, database=None,
                          suppress_health_check=_SLOW_OK, print_blob=True)
PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "ci")
settings.load_profile(PROFILE)

INPUTS: Counter = Counter()
REFUSED: Counter = Counter()


def fed(reader: str, refused: bool = False) -> None:
    """Count one input given to `reader`, and whether it was refused with the reader's own error."""
    INPUTS[reader] += 1
    if refused:
        REFUSED[reader] += 1


def examples(n: int) -> int:
    """`n` examples under the ci profile, as many times more under another as its budget is:
    slow readers (HDF5 through the checking child process, Modbus over TCP) get fewer."""
    return max(1, n * settings.default.max_examples // CI_EXAMPLES)
