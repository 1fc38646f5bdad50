"""The dependency rule: station -> procedures -> drivers, and procedures see only the driver
interfaces. Checked on the import statements of every module."""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def imports_of(package: str) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for path in sorted((REPO / package).rglob("*.py")):
        names: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module)
        out[str(path.relative_to(REPO))] = names
    return out


def offending(package: str, allowed) -> list[str]:
    return [f"{f}: imports {m}" for f, mods in imports_of(package).items() for m in sorted(mods) if not allowed(m)]


def test_drivers_import_neither_procedures_nor_station():
    bad = offending("drivers", lambda m: not m.split(".")[0] in ("procedures", "station"))
    assert not bad, "\n".join(bad)


def test_procedures_see_only_driver_interfaces_and_no_front_end():
    def allowed(m: str) -> bool:
        top = m.split(".")[0]
        if top in ("station", "textual", "textual_plotext"):
            return False
        if top == "drivers":
            return m in ("drivers.interfaces", "drivers.errors")
        return True

    bad = offending("procedures", allowed)
    assert not bad, "\n".join(bad)


def test_the_layering_check_sees_imports():
    # guard against a check that passes because it reads nothing
    assert "drivers.interfaces" in set().union(*imports_of("procedures").values())
    assert "procedures.runner" in set().union(*imports_of("station").values())
