"""The dependency rule: station -> procedures -> drivers, procedures see only the driver
interfaces, and the terminal UI (station/tui) never imports the command line (station/commands).
Checked on the import statements of every module."""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def imported_modules(source: str, module: str, with_names: bool = False) -> set[str]:
    """The modules `source` (the text of the module named `module`, e.g. "station.tui.app";
    "pkg.__init__" for a package) imports, relative imports made absolute. With `with_names`,
    also "M.N" for every `from M import N` (N may be a submodule: `from station import commands`)."""
    package = module.rsplit(".", 1)[0]
    names: set[str] = set()
    for node in ast.walk(ast.parse(source, module)):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                target = f"{base}.{node.module}" if node.module else base
            elif node.module:
                target = node.module
            else:
                continue
            names.add(target)
            if with_names:
                names.update(f"{target}.{a.name}" for a in node.names)
    return names


def imports_of(package: str, with_names: bool = False) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for path in sorted((REPO / package).rglob("*.py")):
        module = ".".join(path.relative_to(REPO).with_suffix("").parts)
        out[str(path.relative_to(REPO))] = imported_modules(path.read_text(), module, with_names)
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
            return m in ("drivers.interfaces", "drivers.errors", "drivers.atomic")
        return True

    bad = offending("procedures", allowed)
    assert not bad, "\n".join(bad)


def is_command_line(module: str) -> bool:
    return module == "station.commands" or module.startswith("station.commands.")


def test_the_terminal_ui_does_not_import_the_command_line():
    """station/tui and station/commands are two front ends over the same jobs (station/*_jobs.py,
    station/services/twins.py, procedures/): the UI imports no command-line module, not even by name
    (`importlib.import_module("station.commands...")`). (`station ui`, a command, starts the UI.)"""
    bad = [f"{path.relative_to(REPO)}: imports {m}" for path in sorted((REPO / "station" / "tui").rglob("*.py"))
           for m in sorted(names_in(path)) if is_command_line(m)]
    assert not bad, "\n".join(bad)


def test_the_command_line_check_sees_every_form_of_import():
    sources = [
        ("station.tui.screens.sweep", "import station.commands.sweep"),
        ("station.tui.screens.sweep", "from station.commands.replay import parse_speed"),
        ("station.tui.screens.sweep", "from station.commands import replay"),
        ("station.tui.screens.sweep", "from station import commands"),
        ("station.tui.app", "from ..commands import push"),
        ("station.tui.screens.sweep", "from ... import commands"),
        ("station.tui.screens.sweep", "from ...commands.push import AUDIT_NAME"),
        ("station.tui.__init__", "from ..commands.replay import replay_sweep"),
    ]
    for module, text in sources:
        names = imported_modules(text, module, with_names=True)
        assert any(is_command_line(m) for m in names), text
    # ... and not the modules beside it
    assert not any(is_command_line(m) for m in imported_modules(
        "from station.services.jobs import replay_sweep\nfrom .common import StationScreen\nimport station.commandsx",
        "station.tui.screens.sweep", with_names=True))


def test_the_layering_check_sees_imports():
    # guard against a check that passes because it reads nothing
    assert "drivers.interfaces" in set().union(*imports_of("procedures").values())
    assert "procedures.engine.runner" in set().union(*imports_of("station").values())


def test_the_audit_sink_is_the_only_writer_of_the_audit_log():
    """Procedures yield AuditRecord events; procedures.compensation.audit.AuditSink alone appends them. No other
    module calls `<audit log>.append(...)` or appends an AuditEntry it builds."""
    bad = []
    for top in ("station", "procedures"):
        for path in sorted((REPO / top).rglob("*.py")):
            rel = str(path.relative_to(REPO))
            if rel == "procedures/compensation/audit.py":
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "append"):
                    continue
                owner = ast.unparse(node.func.value)
                built = [a for a in node.args if isinstance(a, ast.Call) and ast.unparse(a.func).endswith("AuditEntry")]
                if "audit" in owner.lower() or built:
                    bad.append(f"{rel}:{node.lineno}: {ast.unparse(node)[:80]}")
    assert not bad, "\n".join(bad)


def is_drivers(module: str) -> bool:
    return module == "drivers" or module.startswith("drivers.")


def names_in(path: Path) -> set[str]:
    """Every module `path` names: its imports (relative ones made absolute, "M.N" for `from M
    import N`) and module names given as strings (`importlib.import_module("drivers.x")`)."""
    module = ".".join(path.relative_to(REPO).with_suffix("").parts)
    source = path.read_text()
    names = imported_modules(source, module, with_names=True)
    names |= {n.value for n in ast.walk(ast.parse(source)) if isinstance(n, ast.Constant) and isinstance(n.value, str)
              and n.value.strip() == n.value and " " not in n.value}
    return names


def test_front_ends_ask_the_devices_through_services():
    """station/tui and station/commands import nothing from drivers/: device questions (a fault's
    text, soft limits, the value types) go through station/services (the ServoAxis interface,
    services/wiring.py, services/devices.py), so a new drive family leaves the front ends alone."""
    bad = []
    for front in ("station/tui", "station/commands"):
        for path in sorted((REPO / front).rglob("*.py")):
            bad += [f"{path.relative_to(REPO)}: imports {m}" for m in sorted(names_in(path)) if is_drivers(m)]
    assert not bad, "\n".join(bad)


CATALOG_WRITES = ("station.catalog.writer.register", "station.catalog.writer.CatalogSink",  # what writes
                  "station.catalog.files")  # (store: reading; only the services write through it)


def test_no_front_end_writes_the_catalog():
    """The catalog is written by the runner's sink and by the services that make models, tables
    and reports (issue 23): station/tui, station/commands and station/web may hand a job the
    station's catalog (`catalog_for`), never register a file or hold a sink themselves. (The
    `station catalog` command is the catalog's own maintenance: sync, rebuild, check.)"""
    bad = []
    for front in ("station/tui", "station/commands", "station/web"):
        for path in sorted((REPO / front).rglob("*.py")):
            if path.name == "catalog.py" and front == "station/commands":
                continue  # `station catalog sync|rebuild|check` is the catalog's own maintenance
            bad += [f"{path.relative_to(REPO)}: imports {m}" for m in sorted(names_in(path))
                    if any(m == w or m.startswith(w + ".") for w in CATALOG_WRITES)]
    assert not bad, "\n".join(bad)


def test_services_are_plain_python():
    """station/services is the layer every front end calls: no Textual, no argparse."""
    def front_end(m: str) -> bool:
        return m.split(".")[0] in ("textual", "textual_plotext", "argparse") or m.startswith("station.tui") \
            or m.startswith("station.commands")

    bad = [f"{f}: imports {m}" for f, mods in imports_of("station/services").items() for m in sorted(mods) if front_end(m)]
    assert not bad, "\n".join(bad)


def test_the_front_end_checks_see_every_form_of_import():
    sources = [
        ("station.tui.screens.rig", "from drivers.interfaces import DriveLimits"),
        ("station.commands.sim", "import drivers.sim.rig"),
        ("station.commands.sim", "from drivers import errors"),
    ]
    for module, text in sources:
        assert any(is_drivers(m) for m in imported_modules(text, module, with_names=True)), text
    assert not any(is_drivers(m) for m in imported_modules("from station.services.devices import DriveLimits",
                                                           "station.tui.screens.rig", with_names=True))


# -- no import cycle ---------------------------------------------------------------------------------
CYCLE_PACKAGES = ("station", "procedures", "drivers")


def module_graph() -> dict[str, set[str]]:
    """Module -> the modules of CYCLE_PACKAGES it imports at module level (not inside a function:
    a deferred import runs after both modules are loaded, and is how a cycle is broken on
    purpose), `from P import M` counted as an import of P.M when P.M is a module."""
    files: dict[str, Path] = {}
    for top in CYCLE_PACKAGES:
        for path in sorted((REPO / top).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            files[name] = path
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        is_pkg = path.name == "__init__.py"
        package = name if is_pkg else name.rsplit(".", 1)[0]
        edges: set[str] = set()
        tree = ast.parse(path.read_text(), str(path))
        for node in _module_level(tree.body):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                    mod = f"{base}.{node.module}" if node.module else base
                else:
                    mod = node.module or ""
                targets = [mod] + [f"{mod}.{a.name}" for a in node.names]
            else:
                continue
            for t in targets:
                # an import of a.b.c runs a/__init__, a/b/__init__ and a/b/c
                pieces = t.split(".")
                for i in range(1, len(pieces) + 1):
                    m = ".".join(pieces[:i])
                    # a package is loaded before its submodules anyway: no edge to an ancestor
                    if m in files and m != name and not name.startswith(m + "."):
                        edges.add(m)
        graph[name] = edges
    return graph


def _module_level(body):
    """The statements run when the module is imported: the top level, and inside if/try/with
    blocks there (not functions or classes' methods; `if TYPE_CHECKING:` is never run)."""
    for node in body:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            yield from _module_level(node.orelse)
            continue
        yield node
        for field_name in ("body", "orelse", "finalbody", "handlers"):
            inner = getattr(node, field_name, None)
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) or not isinstance(inner, list):
                continue
            if isinstance(node, ast.ClassDef) and field_name == "body":
                yield from (n for n in inner if isinstance(n, (ast.Import, ast.ImportFrom)))
                continue
            yield from _module_level(inner)


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of `graph` as [a, b, ..., a], or None."""
    state: dict[str, int] = {}  # 1 on the path, 2 done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state:
            found = visit(start)
            if found:
                return found
    return None


def test_no_import_cycle():
    """station/, procedures/ and drivers/ import each other without a cycle (module-level imports):
    a cycle makes what works depend on which module happens to be imported first."""
    graph = module_graph()
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_the_cycle_check_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None
    graph = module_graph()
    assert "procedures.engine.runner" in graph["station.services.jobs"]  # it reads the imports
    assert "drivers.interfaces" in graph["procedures.acquisition.sweep"]
