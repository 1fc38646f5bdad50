"""The command line's contract, over every command and every option (issue 31, item 4).

For every option of every command, found from the argparse parsers themselves (a new option is
covered without touching this file), bad and odd values (empty, negative, zero, NaN, inf, huge,
wrong type, a decimal comma, a binary file, a missing file, a folder, a read-only folder as an
unprivileged user) give exit 0 with the command's output, or exit 2 with one line; never a
traceback, never a value outside its kind's bounds accepted, never more memory than a cap.

Two levels, so the CI profile fits about a minute on two cores:
- parse level, in-process, every option x every value: the option's converter (`type=`, the one
  parser of its kind in station/values.py) and its `choices` decide, exactly as argparse calls
  them. A value accepted must lie within its kind's bounds (checked here against the kind's
  declared bounds, not by calling the parser again); any exception other than argparse's own
  refusals is a traceback. Plus hypothesis-generated text for every option.
- full path, a subprocess per example (the real `station`, as user nobody when the tests run as
  root, with RLIMIT_AS capped): a bounded sample of (command, option, bad value), the other
  arguments filled with good values, so the command runs as far as the value lets it.

Profiles (tests/fuzz/budget.py): HYPOTHESIS_PROFILE=long gives 50 times the generated values and
the subprocess sample. The figures (commands x options x values, tracebacks, out-of-range accepted,
largest peak memory) are printed at the end of the module.
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
from collections import Counter
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import tests.fuzz.budget as budget  # noqa: F401  (registers and loads the ci / long profiles)
from station import values as V
from station.cli import build_parser

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "recordings" / "calibration-6legs.h5"
LONG = budget.PROFILE != "ci"
SUBPROCESS_EXAMPLES = int(os.environ.get("STATION_CONTRACT_RUNS", 16 * (50 if LONG else 1)))
"""Full-path examples (about 1-2 s of CPU each, one per subprocess); STATION_CONTRACT_RUNS=N
sets another number (the long profile's 800 take about 40 min on a busy 2-core machine)."""
GENERATED_PER_OPTION = int(os.environ.get("STATION_CONTRACT_STRINGS", 30 * (50 if LONG else 1)))
"""Hypothesis-generated strings per option at the parse level (in-process, about 1 ms each with
hypothesis' own work); STATION_CONTRACT_STRINGS=N sets another number."""
MEMORY_CAP_BYTES = 4 * 1024**3
"""RLIMIT_AS of each subprocess: address space, not resident memory (numpy and BLAS reserve
hundreds of MB they never touch); a command that grows without bound fails inside it."""
TIMEOUT_S = 30.0
"""A command still working after this (a value accepted that asks for long work, e.g. a server)
is stopped and counted, not failed: its memory stayed within the cap meanwhile."""
SERVERS = {"sim", "web", "ui", "recordings"}
"""Commands that run until stopped (or need a terminal), or for minutes whatever the value
(`recordings` regenerates every sample): at the full path only their refusals."""
RC1_MEANS = {"verify": "a leg did not pass", "compare": "a station flagged", "catalog": "problems found",
             "diagnose": "a self-check trial wrong", "replay": "differs from the recording",
             "sweep": "not completed", "run": "not completed", "push": "cancelled", "rollback": "cancelled"}
"""Commands whose exit code 1 is a result (documented in their help), not an error."""
EXEMPT = {("web", "--host"): "the web engineer's host and authentication rule (issue 31, item 6)"}
"""Valued options without a kind of station/values.py, each with why."""

FIGURES: Counter = Counter()
PEAK_KB: dict[str, int] = {}
DEBUG_FULL_PATH = os.environ.get("STATION_CONTRACT_SHOW")  # print every full-path run (argv, exit, line)


# -- discovery -------------------------------------------------------------------------------------

def _commands(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    """(command path, its parser) for every command and sub-command (`catalog rebuild`)."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield path, parser
        return
    for name, sub in subs[0].choices.items():
        yield from _commands(sub, path + (name,))


def _valued(parser: argparse.ArgumentParser):
    """The actions that take a value (not flags, --help, --version or sub-commands)."""
    for a in parser._actions:
        if isinstance(a, (argparse._HelpAction, argparse._VersionAction, argparse._SubParsersAction)):
            continue
        if a.nargs == 0:
            continue
        yield a


def _name(a: argparse.Action) -> str:
    return a.option_strings[-1] if a.option_strings else a.dest


PARSER = build_parser(None)
COMMANDS = {" ".join(path): p for path, p in _commands(PARSER) if path}
OPTIONS = [(cmd, a) for cmd, p in COMMANDS.items() for a in _valued(p)]
FIGURES["parse: commands"] = len(COMMANDS)
FIGURES["parse: options"] = len(OPTIONS)


def test_every_command_and_option_is_found():
    assert len(COMMANDS) >= 26 and len(OPTIONS) >= 150, (len(COMMANDS), len(OPTIONS))


def test_every_valued_option_has_a_kind_or_choices():
    """No bare `type=float`/`type=int`/str: each value is read by one parser of station/values.py."""
    missing = [f"{cmd} {_name(a)}" for cmd, a in OPTIONS
               if a.choices is None and not hasattr(a.type, "kind") and (cmd.split()[0], _name(a)) not in EXEMPT]
    assert missing == []


# -- the values ------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def place():
    """A folder any user can use, with the files the values and the fillers name."""
    root = Path(tempfile.mkdtemp(prefix="station-contract-"))
    root.chmod(0o777)
    (root / "binary.bin").write_bytes(bytes(range(256)) * 64)
    (root / "empty.txt").write_text("")
    (root / "targets.txt").write_text("-10\n0\n10\n")
    (root / "folder").mkdir()
    ro = root / "readonly"
    ro.mkdir()
    (ro / "inside.txt").write_text("1\n")
    ro.chmod(0o555)
    big = root / "sparse-20MB.txt"
    with open(big, "wb") as f:  # a huge text file, made sparse: refused by size, never read whole
        f.truncate(20_000_000)
    for p in root.rglob("*"):
        if p.is_file():
            p.chmod(0o644)
    yield root
    ro.chmod(0o755)
    shutil.rmtree(root, ignore_errors=True)


NUMBERS = ["", " ", "-5", "-1", "0", "-0", "0.0", "1", "5", "12.5", "nan", "NaN", "inf", "-inf", "1e400",
           "1e308", "99999999999999999999", "4294967296", "70000", "1,5", "1.5.2", "0x10", "1_000", "1e-9",
           "abc", "--", "٣", "\u00a0", "1 000", "5mm", "2026-02-30", "2026-03-14", "today", "all", "1-6", "6-1",
           "1,,2", "0-3", "auto", "none", "max", "HX-0042", "3=HX-0042", "A/../HX-0042", "a\x01b", "x" * 5000,
           "sqlite:///nope.sqlite", "postgresql://u:p@127.0.0.1:5999/x", "ftp://x", "fleet:HX300", "sim:default",
           "~0", "~0/x.h5", "~/x.h5"]
"""Literal values tried for every option (the issue's list and the slips seen at the bench)."""


def _file_values(place: Path) -> list[str]:
    return [str(place / "binary.bin"), str(place / "missing.h5"), str(place / "folder"), str(place / "readonly"),
            str(place / "readonly" / "out.h5"), str(place / "readonly" / "inside.txt"), str(place / "empty.txt"),
            str(place / "sparse-20MB.txt"), str(place / "no" / "such" / "sub"), str(SAMPLE)]


# -- the parse level -------------------------------------------------------------------------------

def _within(kind, value) -> str | None:
    """Why `value` (accepted by `kind`'s parser) is outside what the kind declares; None if inside.
    The bounds are read from the kind's fields, independently of its parse()."""
    if isinstance(kind, V.Kind):
        if any(value is meaning for _, meaning in kind.words) or any(value == m for _, m in kind.words if m is not None):
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"not a number: {value!r}"
        if not math.isfinite(value):
            return f"not finite: {value!r}"
        if kind.integer and not isinstance(value, int):
            return f"not whole: {value!r}"
        if kind.lo is not None and (value <= kind.lo if kind.lo_open else value < kind.lo):
            return f"below {kind.range_text()}: {value!r}"
        if kind.hi is not None and (value >= kind.hi if kind.hi_open else value > kind.hi):
            return f"above {kind.range_text()}: {value!r}"
        return None
    if isinstance(kind, V.TextKind) and kind.empty_ok and value == "":
        return None  # "not stated" (an operator, a reason left blank)
    if not isinstance(value, str) or not value.strip() or any(ord(c) < 32 or ord(c) == 127 for c in value):
        return f"empty or control characters: {value!r}"
    if isinstance(kind, V.PathKind):
        p = Path(value).expanduser()
        if kind.role in ("in",) and not p.is_file():
            return f"not an existing file: {value}"
        if kind.role == "in" and kind.text and b"\x00" in p.read_bytes()[:65536]:
            return f"a binary file taken for text: {value}"
        if kind.max_bytes is not None and kind.role == "in" and p.stat().st_size > kind.max_bytes:
            return f"bigger than {kind.max_bytes} bytes: {value}"
        if kind.role in ("out", "dir_out", "path_out") and not p.parent.is_dir():
            return f"its folder does not exist: {value}"
        if kind.role == "out" and p.is_dir():
            return f"a folder taken as an output file: {value}"
        if kind.role == "in_dir" and not p.is_dir():
            return f"not a folder: {value}"
    return None


def _convert(action: argparse.Action, text: str):
    """What argparse does with `text` for `action`: ("refused", message) or ("accepted", value);
    any other exception escapes (a traceback at the command line)."""
    try:
        value = action.type(text) if action.type is not None else text
    except (argparse.ArgumentTypeError, TypeError, ValueError) as exc:  # argparse's refusals
        return "refused", str(exc)
    if action.choices is not None and value not in action.choices:
        return "refused", "invalid choice"
    return "accepted", value


def _check_one(cmd: str, action: argparse.Action, text: str) -> None:
    FIGURES["parse: values tried"] += 1
    try:
        verdict, value = _convert(action, text)
    except Exception as exc:  # noqa: BLE001  (the test's point: nothing else may escape)
        FIGURES["parse: tracebacks"] += 1
        raise AssertionError(f"station {cmd} {_name(action)} {text[:80]!r}: {type(exc).__name__}: {exc}") from exc
    if verdict == "refused":
        FIGURES["parse: refused"] += 1
        assert "\n" not in value.strip(), f"station {cmd} {_name(action)} {text[:80]!r}: refusal of several lines"
        return
    FIGURES["parse: accepted"] += 1
    kind = getattr(action.type, "kind", None)
    if kind is not None:
        why = _within(kind, value)
        if why:
            FIGURES["parse: out-of-range accepted"] += 1
            raise AssertionError(f"station {cmd} {_name(action)} {text[:80]!r} accepted, {why}")


def test_every_option_with_every_literal_value(place):
    for cmd, action in OPTIONS:
        for text in NUMBERS + _file_values(place):
            _check_one(cmd, action, text)


TEXT = st.one_of(
    st.text(max_size=40),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-(10**30), max_value=10**30).map(str),
    st.decimals(allow_nan=True, allow_infinity=True).map(str),
    st.from_regex(r"[+-]?\d{1,6}[.,]\d{1,4}", fullmatch=True),
    st.from_regex(r"\d{4}-\d{1,2}-\d{1,2}", fullmatch=True),
    st.from_regex(r"[0-9, -]{1,12}", fullmatch=True),
)


@pytest.mark.parametrize("cmd,action", OPTIONS, ids=[f"{c}:{_name(a)}" for c, a in OPTIONS])
def test_every_option_with_generated_text(cmd, action):
    @settings(max_examples=GENERATED_PER_OPTION, deadline=None, derandomize=not LONG, database=None)
    @given(TEXT)
    def one(text):
        _check_one(cmd, action, text)
    one()


# -- the full path ---------------------------------------------------------------------------------

def _good(action: argparse.Action, place: Path, files: dict[str, Path], n: int) -> list[str]:
    """A value `action` accepts, for filling the arguments not under test."""
    kind = getattr(action.type, "kind", None)
    count = 2 if action.nargs == 2 else 1
    if action.choices is not None:
        return [str(list(action.choices)[0])] * count
    if isinstance(kind, V.PathKind):
        if kind.role == "in":
            name = kind.name
            path = (files["model"] if "model" in name else files["table"] if "table" in name else
                    files["targets"] if "targets" in name else files["config"] if "config" in name or "TOML" in name
                    else files["csv"] if "CSV" in name else SAMPLE)
            return [str(path)] * count
        if kind.role == "in_dir":
            return [str(place)]
        suffix = {"out": ".h5", "log": ".jsonl"}.get(kind.role, "")
        return [str(place / f"out-{n}{suffix}")]
    if kind is V.SERIAL:
        return ["HX-0042"]
    if kind is V.LEG_SERIAL:
        return ["1=HX-0042"]
    if kind is V.CATALOG:
        return [str(files["catalog"])]
    if kind is not None and getattr(kind, "example", ""):
        ex = kind.example.split(" ")[0].rstrip(",")
        return [ex] * count
    if action.dest == "host":
        return ["127.0.0.1"]
    return ["1"] * count


def _argv(cmd: str, target: argparse.Action, text: str, place: Path, files: dict[str, Path], n: int) -> list[str]:
    """`station CMD ... TARGET TEXT`, every other required argument filled with a good value (one
    of a required mutually exclusive group: the simulated one where there is one)."""
    parser = COMMANDS[cmd]
    argv = cmd.split()
    groups = [g for g in parser._mutually_exclusive_groups if g.required]
    chosen = set()
    for g in groups:
        if target in g._group_actions:
            chosen.add(id(target))
            continue
        pick = next((a for a in g._group_actions if a.dest == "sim"), g._group_actions[0])
        chosen.add(id(pick))
        if pick.nargs == 0:
            argv.append(pick.option_strings[0])
        elif pick.option_strings:
            argv += [pick.option_strings[0], *_good(pick, place, files, n)]
        else:
            argv += _good(pick, place, files, n)
    in_group = {id(a) for g in groups for a in g._group_actions}
    for a in _valued(parser):
        needed = a.required or (not a.option_strings and a.nargs not in ("?", "*")) or _name(a) == "--out"
        if a is target or id(a) in in_group or not needed:  # --out: optional to argparse, needed by sweep's run()
            continue
        argv += ([a.option_strings[0]] if a.option_strings else []) + _good(a, place, files, n)
    count = 2 if target.nargs == 2 else 1
    value = [text] * count
    argv += ([target.option_strings[0], *value] if target.option_strings else value)
    if "--yes" in parser._option_string_actions:
        argv.append("--yes")
    if "--time-scale" in parser._option_string_actions and _name(target) != "--time-scale":
        argv += ["--time-scale", "0"]
    return argv


def _unprivileged() -> list[str]:
    """The command prefix that runs the child as user nobody when we are root (root ignores file
    permissions, so a read-only folder would not be one), with the interpreter any user can run."""
    if os.geteuid() != 0 or not shutil.which("setpriv"):
        return [sys.executable]
    system = Path("/usr/bin/python3")
    same = system.exists() and subprocess.run([str(system), "-c", "import sys; print(sys.version_info[:2])"],
                                              capture_output=True, text=True).stdout.strip() == str(sys.version_info[:2])
    if same:
        return ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", str(system)]
    # another interpreter version: root without any capability respects permission bits as well
    return ["setpriv", "--bounding-set=-all", "--inh-caps=-all", sys.executable]


CHILD = """
import atexit, os, resource, sys
resource.setrlimit(resource.RLIMIT_AS, ({cap}, {cap}))

def _peak():
    # VmHWM: this program's own peak. ru_maxrss of the child is not: a fork copies the test worker's
    # resident pages, and exec keeps that high-water mark in the process's rusage
    with open("/proc/self/status") as status:
        kb = next((line.split()[1] for line in status if line.startswith("VmHWM:")), "")
    os.write(int(os.environ["STATION_TEST_PEAK_FD"]), kb.encode())

atexit.register(_peak)
from station.cli import main
sys.exit(main(sys.argv[1:]))
"""


def run_station(argv: list[str], cwd: Path, env_home: Path, timeout_s: float = TIMEOUT_S
                ) -> tuple[int | None, str, str, int]:
    """(exit code or None when stopped at TIMEOUT_S, stdout, stderr, peak resident memory kB) of
    `station ARGV` in a child, unprivileged and capped at MEMORY_CAP_BYTES of address space."""
    code = CHILD.format(cap=MEMORY_CAP_BYTES)
    env = {"PYTHONPATH": os.pathsep.join([sysconfig.get_paths()["purelib"], str(REPO)]),  # children inherit it
           "PATH": "/usr/bin:/bin", "HOME": str(env_home), "MPLCONFIGDIR": str(env_home / "mpl"), "LANG": "C.UTF-8",
           "OPENBLAS_NUM_THREADS": "1", "STATION_SIM_NOISE_SEED": "7"}
    peak_r, peak_w = os.pipe()
    env["STATION_TEST_PEAK_FD"] = str(peak_w)
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        try:
            proc = subprocess.Popen([*_unprivileged(), "-c", code, *argv], cwd=cwd, env=env, stdout=out, stderr=err,
                                    stdin=subprocess.DEVNULL, pass_fds=(peak_w,))
        finally:
            os.close(peak_w)
        t_end = time.monotonic() + timeout_s
        status = None
        while status is None:
            pid, st_, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                status = st_
                break
            if time.monotonic() > t_end:
                proc.kill()
                _, st_, usage = os.wait4(proc.pid, 0)
                status = None
                break
            time.sleep(0.05)
        proc.returncode = 0  # reaped by wait4 above
        out.seek(0)
        err.seek(0)
        rc = os.waitstatus_to_exitcode(status) if status is not None else None
        with os.fdopen(peak_r, "rb") as peak:
            reported = peak.read().decode().strip()
        # killed before its exit handlers ran: the rusage figure, an upper side
        peak_kb = int(reported) if reported.isdigit() else usage.ru_maxrss
        return rc, out.read().decode(errors="replace"), err.read().decode(errors="replace"), peak_kb


@pytest.fixture(scope="module")
def files(place):
    """A model, a table, a config and a catalog for the fillers, made once by the real commands."""
    from station.cli import main

    made = {"targets": place / "targets.txt", "config": place / "station.toml"}
    (place / "runs").mkdir()
    made["config"].write_text(f'[station]\nrecordings_dir = "{place / "runs"}"\n')
    made["model"] = place / "model.json"
    assert main(["fit", str(SAMPLE), "--legs", "1", "--out", str(made["model"])]) == 0
    made["table"] = place / "table.csv"
    assert main(["table", str(made["model"]), "--out", str(made["table"])]) == 0
    made["csv"] = place / "export.csv"
    assert main(["export", str(SAMPLE), "--out", str(made["csv"])]) == 0
    made["catalog"] = place / "catalog.sqlite"
    assert main(["catalog", "rebuild", str(place / "runs"), "--db", str(made["catalog"])]) == 0
    for p in place.rglob("*"):
        p.chmod(0o777 if p.is_dir() and p.name != "readonly" else 0o644 if p.is_file() else p.stat().st_mode)
    return made


BAD = ["", "-1", "0", "nan", "inf", "1e400", "99999999999999999999", "abc", "1,5", "BINARY", "MISSING", "FOLDER",
       "READONLY", "EMPTY", "TEXT", "SESSION", "LOWEST", "HIGHEST", "HIGHEST", "LOWEST"]
"""The issue's list of values for the full path; the file ones are placed per example. LOWEST and
HIGHEST are the option's kind's own bounds, which its parser accepts: they reach the command's
run() (a plan of 1000 cycles, 100 000 000 poses, the last seed), where the sizes are checked."""


def _bad_text(token: str, action: argparse.Action, place: Path) -> str:
    kind = getattr(action.type, "kind", None)
    if token in ("LOWEST", "HIGHEST"):
        bound = getattr(kind, "lo" if token == "LOWEST" else "hi", None)
        if bound is None or getattr(kind, "lo_open" if token == "LOWEST" else "hi_open", False):
            return "5"
        return str(int(bound)) if getattr(kind, "integer", False) else repr(float(bound))
    return {"BINARY": str(place / "binary.bin"), "MISSING": str(place / "missing.h5"), "FOLDER": str(place / "folder"),
            "READONLY": str(place / "readonly" / "out"), "EMPTY": str(place / "empty.txt"),
            "TEXT": str(place / "targets.txt"), "SESSION": str(SAMPLE)}.get(token, token)


FULL = [(cmd, a) for cmd, a in OPTIONS if cmd.split()[0] not in SERVERS]


@settings(max_examples=SUBPROCESS_EXAMPLES, deadline=None, derandomize=not LONG, database=None)
@given(st.data())
def _full_path(place, files, data):
    cmd, action = data.draw(st.sampled_from(FULL + [(c, a) for c, a in OPTIONS if c in SERVERS]), label="option")
    text = _bad_text(data.draw(st.sampled_from(BAD), label="value"), action, place)
    if cmd in SERVERS and _convert(action, text)[0] == "accepted":
        FIGURES["subprocess: server accepted, not started"] += 1
        return
    n = FIGURES["subprocess: runs"]
    argv = _argv(cmd, action, text, place, files, n)
    cwd = place / "readonly" if data.draw(st.booleans(), label="in the read-only folder") else place
    rc, out, err, peak_kb = run_station(argv, cwd, place)
    FIGURES["subprocess: runs"] += 1
    if peak_kb > max(PEAK_KB.values(), default=0):
        PEAK_KB[" ".join(argv)[:200]] = peak_kb
    shown = f"station {' '.join(argv)[:300]} (in {cwd.name}) -> rc {rc}\n{err[-2000:]}"
    if DEBUG_FULL_PATH:
        sys.__stdout__.write(shown.rstrip() + "\n\n")
    if rc == 2 and (_name(action) in err or text[:40] in err):
        FIGURES["subprocess: refused naming the option or value"] += 1
    if "Traceback" in err or "Traceback" in out:
        FIGURES["subprocess: tracebacks"] += 1
        raise AssertionError(f"traceback: {shown}")
    if rc is None:
        FIGURES["subprocess: stopped at the time limit"] += 1
        return
    FIGURES[f"subprocess: exit {rc}"] += 1
    assert rc in (0, 1, 2), shown
    if rc == 1:
        assert cmd.split()[0] in RC1_MEANS, f"exit 1 from a command where it means nothing: {shown}"
    if rc == 2:
        lines = [x for x in err.splitlines() if x.strip() and not x.startswith(("warning:", "note:"))]
        assert len(lines) == 1 and lines[0].startswith("station "), f"not one line: {shown}"


def test_full_path_sample_in_subprocesses(place, files):
    t0 = time.monotonic()
    _full_path(place, files)
    FIGURES["subprocess: seconds"] = round(time.monotonic() - t0)
    assert FIGURES["subprocess: runs"] > 0


def test_zz_figures(capsys):
    """The figures of this run (printed at the end; also the closing note's numbers)."""
    peak = max(PEAK_KB.values(), default=0)
    lines = [f"cli contract ({budget.PROFILE} profile): {FIGURES['parse: commands']} commands, {FIGURES['parse: options']} "
             f"options, {FIGURES['parse: values tried']} values tried at the parse level "
             f"({FIGURES['parse: refused']} refused, {FIGURES['parse: accepted']} accepted), "
             f"{FIGURES['parse: tracebacks']} tracebacks, {FIGURES['parse: out-of-range accepted']} out of range accepted",
             f"cli contract: {FIGURES['subprocess: runs']} subprocess runs (exit 0: {FIGURES['subprocess: exit 0']}, "
             f"1: {FIGURES['subprocess: exit 1']}, 2: {FIGURES['subprocess: exit 2']} of which "
             f"{FIGURES['subprocess: refused naming the option or value']} naming the option or value, stopped at "
             f"{TIMEOUT_S:g} s: "
             f"{FIGURES['subprocess: stopped at the time limit']}) in {FIGURES['subprocess: seconds']} s, "
             f"{FIGURES['subprocess: tracebacks']} tracebacks, "
             f"largest peak memory {peak / 1024:.0f} MB (cap {MEMORY_CAP_BYTES / 1024**3:g} GB of address space)"]
    with capsys.disabled():  # past the output capture, as tests/fuzz/conftest.py prints its counts
        print("\n" + "\n".join(lines))
    assert FIGURES["parse: tracebacks"] == 0 and FIGURES["parse: out-of-range accepted"] == 0
    assert FIGURES["subprocess: tracebacks"] == 0
