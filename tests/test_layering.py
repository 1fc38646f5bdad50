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
    """Of drivers/, procedures see the interfaces (and their errors and atomic writes) and the plant
    (drivers/plant): the leg's physics is a model, not a device (numpy only, no I/O, no protocol), and
    the diagnosis' simulated-plant twin and the synthetic sessions need the same physics the
    simulated devices run on, not a copy of it. No concrete device: not drivers.sim, drivers.modbus..."""
    def allowed(m: str) -> bool:
        top = m.split(".")[0]
        if top in ("station", "textual", "textual_plotext"):
            return False
        if top == "drivers":
            return m in ("drivers.interfaces", "drivers.errors", "drivers.atomic") or m.startswith("drivers.plant.")
        return True

    bad = offending("procedures", allowed)
    assert not bad, "\n".join(bad)


PLANT_MAY_IMPORT = {"__future__", "math", "dataclasses", "numpy"}


def test_the_plant_is_pure_physics():
    """drivers/plant, which procedures may import, holds the leg's physics alone: numpy and a few
    standard modules, nothing of the devices, the protocols, files or the other layers."""
    bad = offending("drivers/plant", lambda m: m.split(".")[0] in PLANT_MAY_IMPORT or m.startswith("drivers.plant."))
    assert not bad, "\n".join(bad)
    assert "numpy" in set().union(*imports_of("drivers/plant").values())  # it reads the plant's imports


ONE_HOME = {"PlantConfig": "drivers/plant/leg.py", "LegPlant": "drivers/plant/leg.py",
            "systematic_error_um": "drivers/plant/leg.py", "default_leg_configs": "drivers/plant/leg.py",
            "synth_session": "procedures/synthetic.py", "plant_twin": "procedures/diagnosis/twin.py"}


def test_the_leg_physics_and_the_sessions_made_from_it_have_one_home():
    """The plant and what is made from it alone are defined once (issue 32: the simulators, the
    twins and the generators use the plant; none keeps a copy of it)."""
    found: dict[str, list[str]] = {}
    for top in ("station", "procedures", "drivers"):
        for path in sorted((REPO / top).rglob("*.py")):
            for node in ast.parse(path.read_text()).body:
                if isinstance(node, (ast.ClassDef, ast.FunctionDef)) and node.name in ONE_HOME:
                    found.setdefault(node.name, []).append(str(path.relative_to(REPO)))
    assert found == {name: [home] for name, home in ONE_HOME.items()}


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


def module_files() -> dict[str, Path]:
    """Module name -> file, for every module of CYCLE_PACKAGES (a package by its own name)."""
    files: dict[str, Path] = {}
    for top in CYCLE_PACKAGES:
        for path in sorted((REPO / top).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            files[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return files


def module_graph() -> dict[str, set[str]]:
    """Module -> the modules of CYCLE_PACKAGES it imports anywhere: at module level, inside a
    function, under `if TYPE_CHECKING:`. A deferred or type-only import still says that each module
    needs the other; moving an import into a function hides a circle, it does not break it.
    `from P import M` counts as an import of P.M when P.M is a module."""
    files = module_files()
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        edges: set[str] = set()
        for target in imported_modules(path.read_text(), name + (".__init__" if path.name == "__init__.py" else ""),
                                       with_names=True):
            # an import of a.b.c runs a/__init__, a/b/__init__ and a/b/c
            pieces = target.split(".")
            for i in range(1, len(pieces) + 1):
                m = ".".join(pieces[:i])
                # a package is loaded before its submodules anyway: no edge to an ancestor
                if m in files and m != name and not name.startswith(m + "."):
                    edges.add(m)
        graph[name] = edges
    return graph


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The circles of `graph`: its strongly connected groups of more than one module (Tarjan),
    each sorted. Every module of a group reaches every other one through imports."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[list[str]] = []

    def visit(node: str) -> None:  # recursive: the graph is a few hundred modules deep at most
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            group = []
            while True:
                m = stack.pop()
                on_stack.discard(m)
                group.append(m)
                if m == node:
                    break
            if len(group) > 1:
                circles.append(sorted(group))

    for start in sorted(graph):
        if start not in index:
            visit(start)
    return sorted(circles)


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
    """station/, procedures/ and drivers/ import each other without a circle, counting every import
    (inside functions and under TYPE_CHECKING too): a circle makes what works depend on which module
    happens to be imported first, and says two modules are one. The message names each circle and
    one path around it."""
    graph = module_graph()
    circles = import_circles(graph)
    described = []
    for group in circles:
        inside = {m: graph[m] & set(group) for m in group}
        described.append(f"{len(group)} modules: " + " -> ".join(find_cycle(inside)))
    assert not circles, f"{len(circles)} import circle(s):\n" + "\n".join(described)


def test_the_cycle_check_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None
    assert import_circles({"a": {"b"}, "b": {"a", "c"}, "c": set(), "d": {"e"}, "e": {"f"}, "f": {"d"}}) == [
        ["a", "b"], ["d", "e", "f"]]
    assert import_circles({"a": {"b"}, "b": set()}) == []
    graph = module_graph()
    assert "procedures.engine.runner" in graph["station.services.jobs"]  # it reads the imports
    assert "drivers.interfaces" in graph["procedures.acquisition.sweep"]
    # ... and the ones inside functions and under TYPE_CHECKING
    assert "station.cli" in graph["station.launch"]  # inside main()
    assert "station.services.table_jobs" in graph["station.tui.screens.compensation"]  # inside methods


# -- no private name across packages ----------------------------------------------------------------
def private_imports() -> list[str]:
    """Every `from M import _x` (one leading underscore) in station/, procedures/ and drivers/ where
    M lies in another package than the importing module: a private name is its module's own
    business, and one borrowed from elsewhere belongs in a shared, public place."""
    bad = []
    for name, path in module_files().items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                source = f"{base}.{node.module}" if node.module else base
            else:
                source = node.module or ""
            for alias in node.names:
                private = alias.name.startswith("_") and not alias.name.startswith("__")
                if private and source.rsplit(".", 1)[0] != package and source != package:
                    bad.append(f"{path.relative_to(REPO)}:{node.lineno}: {source}.{alias.name}")
    return bad


def test_no_private_name_is_imported_across_packages():
    bad = private_imports()
    assert not bad, "\n".join(bad)


# -- front ends reach procedures through services ---------------------------------------------------
FRONT_ENDS = ("station/commands", "station/tui", "station/web")

FRONT_END_PROCEDURES_ALLOWED: dict[str, set[str]] = {}
"""Empty, and the rule is absolute: a front end (station/commands, station/tui, station/web) reaches
procedures only through station/services (or the catalog's readers, station/catalog), naming
nothing of procedures beyond SHARED_VOCABULARY. The list held 144 module imports in 36 files on
main before issue 32's parts 5 and 6 and was emptied by part 1 (the jobs in station/services);
it stays empty: a new direct import fails."""


SHARED_VOCABULARY = {"procedures.vocabulary", "procedures.io.recording.stage", "procedures.engine.events"}
"""What every layer may name: the input errors every front end raises and catches, how an operation
ended (procedures/vocabulary.py), the stages of a leg's life every view asks for (issue 32: the
shared vocabulary in small modules), and the events a procedure yields (procedures/engine/events.py).
The events are the contract between the procedures and every front end, not a procedure's
internals: the runner hands each one to the sinks (the recorder, the TUI's bridge and state, the
CLI's printer) as the procedure yielded it, and a front end only presents them; a service
translating them into its own types would be a second copy of the same contract."""


def front_end_procedures_imports(shared: set[str] = SHARED_VOCABULARY) -> dict[str, set[str]]:
    """File of a front end -> the procedures modules it imports (anywhere in the file) beyond `shared`."""
    out: dict[str, set[str]] = {}
    for front in FRONT_ENDS:
        for path in sorted((REPO / front).rglob("*.py")):
            module = ".".join(path.relative_to(REPO).with_suffix("").parts)
            mods = {m for m in imported_modules(path.read_text(), module)
                    if m.split(".")[0] == "procedures" and m not in shared}
            if mods:
                out[str(path.relative_to(REPO))] = mods
    return out


def test_front_ends_reach_procedures_only_through_services():
    found = front_end_procedures_imports()
    new = [f"{f}: imports {m}" for f, mods in sorted(found.items()) for m in sorted(mods)]
    assert not FRONT_END_PROCEDURES_ALLOWED, "the list stays empty: move the import behind station/services"
    assert not new, ("a front end imports procedures directly (go through station/services; only "
                     "SHARED_VOCABULARY may be named):\n" + "\n".join(new))


def test_the_new_checks_see_what_they_check():
    type_only = "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from procedures.compensation.push import PushPlan\n"
    in_function = "def run(args):\n    from procedures.fit import fit\n"
    assert "procedures.compensation.push" in imported_modules(type_only, "station.commands.x")
    assert "procedures.fit" in imported_modules(in_function, "station.commands.x")
    found = front_end_procedures_imports(shared=set())  # reads the front ends: they name the vocabulary
    assert found and all(f.startswith(FRONT_ENDS) for f in found)
    assert set().union(*found.values()) <= SHARED_VOCABULARY
    assert "procedures.engine" in imported_modules("from procedures.engine import events as ev", "station.tui.state")


def station_imports_of_tests(folder: str = "tests/procedures") -> dict[str, set[str]]:
    """The station modules each test file under `folder` imports (at the top, in a function, under
    TYPE_CHECKING): file -> modules; files importing none left out."""
    found = {f: {m for m in mods if m.split(".")[0] == "station"} for f, mods in imports_of(folder).items()}
    return {f: mods for f, mods in found.items() if mods}


def test_the_procedures_tests_do_not_import_station():
    """tests/procedures tests the procedures/ layer, which does not depend on station/: its tests
    use procedures (and drivers) only. A test of a station service, the config or the CLI lives
    under tests/station."""
    found = station_imports_of_tests()
    bad = [f"{f}: imports {m}" for f, mods in sorted(found.items()) for m in sorted(mods)]
    assert not bad, "tests under tests/procedures import station (move them to tests/station):\n" + "\n".join(bad)


def test_the_procedures_tests_check_sees_imports():
    # guard against a check that passes because it reads nothing: tests/station imports station,
    # in every form the check must see
    assert station_imports_of_tests("tests/station")
    for text in ("import station.cli", "from station.services.table_jobs import push_table",
                 "def test():\n    from station import interrupt\n",
                 "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from station.services.config import StationConfig\n"):
        assert any(m.split(".")[0] == "station" for m in imported_modules(text, "tests.procedures.x.test_y")), text
