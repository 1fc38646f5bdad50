"""Loads the fuzzing profiles (tests/fuzz/budget.py) and prints the inputs fed to each reader."""

from __future__ import annotations

from tests.fuzz.budget import INPUTS, PROFILE, REFUSED


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if not INPUTS:
        return
    tr = terminalreporter
    tr.section(f"fuzzed inputs per reader (hypothesis profile {PROFILE})")
    for reader in sorted(INPUTS):
        refused = f", {REFUSED[reader]:>7} refused with its own error" if reader in REFUSED else ""
        tr.write_line(f"{reader:<50} {INPUTS[reader]:>7} inputs{refused}")
