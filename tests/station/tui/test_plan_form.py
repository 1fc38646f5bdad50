"""The Sweep screen's form becomes a PlanSpec, converted as `station sweep` converts its
arguments: the same plan, and the same messages for a plan that is refused."""

from __future__ import annotations

import asyncio

import pytest
from textual.widgets import Input, Static

from procedures.acquisition.plan_spec import PlanSpec, plan_from_spec
from station.cli import build_parser, main
from station.commands.sweep import plan_spec as cli_plan_spec
from procedures.vocabulary import InputError
from station.tui.app import StationApp
from tests.station.tui.steps import choose_plan
from station.tui.fields import FIELD_KINDS

pytestmark = pytest.mark.timeout(120)


async def fill_form(pilot, **fields) -> None:
    """Set form fields by id; the plan first, since choosing a plan sets its number of cycles."""
    screen = pilot.app.screen
    if "plan" in fields:
        await choose_plan(pilot, fields.pop("plan"))
    for wid, value in fields.items():
        screen.query_one(f"#{wid.replace('_', '-')}", Input).value = str(value)


def summary(app) -> str:
    return str(app.screen.query_one("#plan-summary", Static).render())


REFUSED = [(dict(cycles=0), ["--cycles", "0"]), (dict(cycles=5, legs="7"), ["--legs", "7"]),
           (dict(legs="1", step=0), ["--step", "0"])]


def test_the_form_and_the_command_line_ask_for_the_same_plan(cfg, size, connected, wait_until, tmp_path, capsys):
    messages = []  # what `station sweep` says about each refused plan (the app captures stderr while it runs)
    for _, argv in REFUSED:
        assert main(["sweep", "--sim", *argv, "--out", str(tmp_path / "never.h5")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("station sweep: error: ")
        messages.append(err.removeprefix("station sweep: error: ").strip())
    assert not (tmp_path / "never.h5").exists()
    asyncio.run(_test_form_and_cli(cfg, size, connected, wait_until, messages))


async def _test_form_and_cli(cfg, size, connected, wait_until, messages):
    app = StationApp(cfg, time_scale=0.0)
    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep screen")
        screen = app.screen
        # the form as it opens: the standard ISO 230-2 cycle on leg 1
        assert screen.plan_spec() == PlanSpec(legs=(1,), kind="iso230", cycles=5, n_targets=11)
        assert screen.build_plan() == plan_from_spec(PlanSpec())

        cases = [
            (dict(legs="2-3", cycles=2, n_targets=7, min_mm=-40, max_mm=60, dwell=0.5),
             ["--legs", "2-3", "--cycles", "2", "--n-targets", "7", "--min-mm", "-40", "--max-mm", "60", "--dwell", "0.5"]),
            (dict(legs="1", cycles="", step=7.5, n_targets=11, min_mm=-90, max_mm=90, dwell=1),
             ["--legs", "1", "--step", "7.5", "--n-targets", "11"]),
            (dict(plan="paper", legs="1-6", step=""), ["--plan", "paper", "--legs", "1-6", "--cycles", "6", "--n-targets", "11"]),
        ]
        for form, argv in cases:
            await fill_form(pilot, **form)
            await pilot.pause()
            cli = cli_plan_spec(build_parser("sweep").parse_args(["sweep", "--sim", *argv]))
            assert screen.plan_spec() == cli, form
            assert screen.build_plan() == plan_from_spec(cli)

        # a step typed while the paper plan is chosen is not asked for: the paper's targets are fixed
        await fill_form(pilot, step=2.5)
        await pilot.pause()
        assert screen.plan_spec().step_mm is None and len(screen.build_plan().targets_mm) == 361

        # refused plans: the summary shows the message `station sweep` prints
        await fill_form(pilot, plan="iso230", step="", legs="1")
        for (form, argv), message in zip(REFUSED, messages):
            await fill_form(pilot, **form)
            await pilot.pause()
            shown = summary(app)
            if argv[0] in ("--cycles", "--step"):
                # a number field: the refusal of its kind's parser (station.values), the one
                # `station sweep --cycles/--step` uses once its options are converted to the kinds
                # (issue 31 part 1); the field is marked invalid
                wid = argv[0].removeprefix("--")
                kind = FIELD_KINDS[wid][0]
                with pytest.raises(InputError) as refused:
                    kind.parse(argv[1], wid)
                assert str(refused.value) in shown, (form, str(refused.value), shown)
                assert screen.query_one(f"#{wid}").has_class("-invalid")
                assert "is not" in message or "must be" in message or "outside" in message  # the CLI refuses it too
            else:
                # the option's own refusal, without what argparse puts around it
                core = message.removeprefix(f"argument {argv[0]}: ").split("; see `station sweep --help`")[0]
                assert core in shown, (form, core, shown)
