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


def pytest_collection_modifyitems(config, items):
    """The long profile runs a test for minutes (the Modbus one about ten): past the suite's
    300 s pytest-timeout, which stays for the CI profile."""
    if PROFILE != "ci":
        import pytest

        for item in items:
            if "tests/fuzz/" in str(item.fspath).replace("\\", "/"):
                item.add_marker(pytest.mark.timeout(3600))
