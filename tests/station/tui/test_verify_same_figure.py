"""One figure, one value (issue 22, item 5): `station verify` and the Compensation page give the
verification ratio on the same basis. Each front end's figure is the one procedures.compensation.verify
computes from the sessions it recorded, normalised to 20 degC (the CLI's --raw: raw on both
sides), so the same data give the same figure in both. The 2.29 / 7.8 / 1.15 of the issue were
a residual RMS on one basis divided by a noise floor on another: this test fails on any such mix
(a raw residual over a normalised floor differs by the ratio of the two floors, here several
times)."""

from __future__ import annotations

import asyncio
import json
import re

import pytest

from procedures.io.recording.reader import read_session
from procedures.compensation.verify import error_basis, verify
from station.cli import main
from station.tui.app import StationApp
from tests.station.tui.steps import open_session

pytestmark = pytest.mark.timeout(240)


def _expected(after_path, before_path, normalise: bool) -> float:
    after, before, _, _ = error_basis(read_session(after_path), read_session(before_path), normalise)
    return verify(after, before, [1])[1].ratio


def test_cli_and_compensation_page_give_the_ratio_on_the_same_basis(recorded_session, cfg, size, wait_until,
                                                                   connected, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # `--sim` keeps the drive memory in runs/ here, where cfg points too
    cfg.recordings_dir = str(tmp_path / "runs")
    assert main(["fit", str(recorded_session), "--legs", "1", "--out", "model.json"]) == 0
    assert main(["table", "model.json", "--out", "table.csv"]) == 0
    assert main(["push", "table.csv", "--leg", "1", "--sim", "--yes"]) == 0
    figures = {}
    for basis, extra in (("normalised", []), ("raw", ["--raw"])):
        rc = main(["verify", "--leg", "1", "--sim", "--before", str(recorded_session), "--out", f"cli-{basis}.h5",
                   "--json", f"cli-{basis}.json", "--noise-seed", "7", *extra])
        assert rc in (0, 1)  # PASS or ABOVE: the figure is what is compared
        figures[basis] = json.loads((tmp_path / f"cli-{basis}.json").read_text())["legs"]["1"]["ratio"]
        assert figures[basis] == _expected(tmp_path / f"cli-{basis}.h5", recorded_session, basis == "normalised")
    printed = capsys.readouterr().out
    assert f"verification ratio (residual RMS / noise floor): {figures['normalised']:.3f}" in printed
    # a raw residual over the normalised floor (the mix the issue saw) is a different figure
    after, before, _, _ = error_basis(read_session(tmp_path / "cli-normalised.h5"), read_session(recorded_session), True)
    raw_after, _, _, _ = error_basis(read_session(tmp_path / "cli-normalised.h5"), None, False)
    mixed = verify(raw_after, None, [1])[1].after.rms_um / verify(after, before, [1])[1].after.noise_floor_um
    assert abs(mixed - figures["normalised"]) > 0.05

    async def page() -> tuple[str, object]:
        app = StationApp(cfg.with_sim_memory(), time_scale=0.0)
        async with app.run_test(size=size) as pilot:
            await connected(pilot)
            await open_session(pilot, wait_until, "f3", recorded_session)
            await wait_until(pilot, lambda: app.analysis is not None, 60, "the fit")
            await pilot.press("f4")
            comp = app.screen
            await pilot.press("v")
            await wait_until(pilot, lambda: app.sweep.label == "verification of leg 1", what="the verification sweep")
            await wait_until(pilot, lambda: comp.verify_text != "", 90, "the verification report")
            return comp.verify_text, app.sweep.out

    text, ui_session = asyncio.run(page())
    shown = float(re.search(r"verification ratio \(residual RMS / noise floor\): ([0-9.]+)", text).group(1))
    # the page's figure is the CLI's function on the page's own recording, on the CLI's default basis
    assert shown == round(_expected(ui_session, recorded_session, True), 3)
    assert "verification error: normalised to 20 degC" in text
