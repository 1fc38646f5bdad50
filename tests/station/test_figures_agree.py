"""One name per definition (issue 17): `station fit`, `station diagnose`, `station report` and
`station iso230` on the committed sample recording; every figure they show under the same name
has the same value, and the figures that used to share a name ("noise floor" of fit vs diagnose,
"range after" of fit vs report) now have different names (docs/figures.md)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from procedures.fit import load_model, save_model
from procedures.fit.figures import LABELS
from procedures.reporting.iso230 import MEANINGS, VALUE_NAMES
from station.cli import main

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "recordings" / "calibration-6legs.h5"
FIGURES_DOC = REPO / "docs" / "figures.md"

pytestmark = pytest.mark.timeout(300)


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """stdout and JSON of the four commands on the sample (capsys is function-scoped: capture
    by hand)."""
    import contextlib
    import io

    tmp = tmp_path_factory.mktemp("figures")
    # fit, iso230 and report normalise to 20 degC by default, diagnose works on the raw error:
    # the same definitions are compared on the same error (raw); the default basis is compared
    # in test_report_agrees_with_fit_and_iso230_on_the_default_basis
    runs = {
        "fit": ["fit", str(SAMPLE), "--out", str(tmp / "model.json"), "--raw"],
        "diagnose": ["diagnose", str(SAMPLE), "--json", str(tmp / "diagnosis.json")],
        "report": ["report", str(SAMPLE), "--out", str(tmp / "report"), "--raw"],
        "iso230": ["iso230", str(SAMPLE), "--json", str(tmp / "iso230.json"), "--raw"],
    }
    text = {}
    for name, argv in runs.items():
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            assert main(argv) == 0, name
        text[name] = buf.getvalue()
    return {
        "text": text,
        "model_path": tmp / "model.json",
        "model": load_model(tmp / "model.json"),
        "diagnosis": json.loads((tmp / "diagnosis.json").read_text()),
        "report": json.loads((tmp / "report" / "summary.json").read_text()),
        "report_md": (tmp / "report" / "summary.md").read_text(),
        "iso230": json.loads((tmp / "iso230.json").read_text()),
    }


def figures_by_command(o) -> dict[str, dict[int, dict[str, float]]]:
    """command -> leg -> {JSON key: value} of every figure it shows (procedures.fit.figures
    keys; ISO 230-2 values as iso230:NAME). A figure of the model a report compensates with is
    the figure of that model; the report fitted it to this recording with the default options,
    as `station fit` did, so it is the same model."""
    out: dict[str, dict[int, dict[str, float]]] = {"fit": {}, "diagnose": {}, "report": {}, "report (model)": {},
                                                   "iso230": {}}
    for leg, lf in o["model"].legs.items():
        s = lf.stats
        out["fit"][leg] = {
            "noise_floor_um": s.noise_floor_um, "within_pass_um": s.within_pass_um,
            "heldout_rms_um": s.heldout_rms_um, "heldout_ratio": s.heldout_ratio,
            "ideal_heldout_ratio": s.ideal_heldout_ratio, "range_before_um": s.range_before_um,
            "heldout_range_um": s.heldout_range_um, "heldout_range_reduction_pct": s.heldout_range_reduction_pct,
        }
    for key, leg in o["diagnosis"]["legs"].items():
        out["diagnose"][int(key)] = {k: leg[k] for k in (
            "noise_floor_um", "repeat_scatter_after_effects_um", "within_pass_scatter_after_effects_um",
            "pass_offset_scatter_after_effects_um")}
    assert o["report"]["model"]["fitted_to_this_session"] is True
    for row in o["report"]["legs"]:
        figs = {k: row[k] for k in ("noise_floor_um", "range_before_um", "residual_range_um",
                                    "residual_range_reduction_pct", "rms_before_um", "residual_rms_um")}
        figs.update({f"iso230:{k}": v for k, v in row["iso230_2"]["before"].items()})
        out["report"][row["leg"]] = figs
        out["report (model)"][row["leg"]] = {"noise_floor_um": row["model_noise_floor_um"],
                                             "heldout_rms_um": row["model_heldout_rms_um"],
                                             "heldout_ratio": row["model_heldout_ratio"]}
    for key, leg in o["iso230"]["legs"].items():
        out["iso230"][int(key)] = {f"iso230:{k}": leg[k] for k in VALUE_NAMES}
    return out


def test_every_figure_shown_by_two_commands_has_one_value(outputs):
    by_cmd = figures_by_command(outputs)
    legs = sorted(by_cmd["fit"])
    assert legs == [1, 2, 3, 4, 5, 6]
    shared = 0
    for leg in legs:
        seen: dict[str, tuple[str, float]] = {}
        for cmd, per_leg in by_cmd.items():
            for key, value in per_leg[leg].items():
                if key in seen:
                    first_cmd, first = seen[key]
                    assert value == pytest.approx(first, rel=1e-12, abs=1e-12), (
                        f"leg {leg}: {key} is {first} from {first_cmd} but {value} from {cmd}")
                    shared += 1
                else:
                    seen[key] = (cmd, value)
    # noise floor (fit, diagnose, report), range before, held-out RMS and ratio (fit, report),
    # the ISO 230-2 values (iso230, report) were compared on every leg
    assert shared >= 6 * (2 + 1 + 2 + 12)
    # every JSON key of a figure is a named figure (or an ISO 230-2 value)
    for per_leg in by_cmd.values():
        for figs in per_leg.values():
            assert all(k in LABELS or k.startswith("iso230:") for k in figs), set(figs) - set(LABELS)


def test_the_formerly_conflicting_figures_have_different_names_and_values(outputs):
    by_cmd = figures_by_command(outputs)
    fit1, diag1, rep1 = by_cmd["fit"][1], by_cmd["diagnose"][1], by_cmd["report"][1]
    # "noise floor": fit's pooled pass-to-pass scatter; what diagnose used to print under that name
    # is the scatter of repeat passes left after the twin and the named effects
    assert LABELS["noise_floor_um"] != LABELS["repeat_scatter_after_effects_um"]
    assert diag1["noise_floor_um"] == fit1["noise_floor_um"]
    assert diag1["repeat_scatter_after_effects_um"] < 0.5 * fit1["noise_floor_um"]  # 0.073 vs 0.708 um
    # "range after": fit's is of the held-out residuals, report's of the in-sample residuals
    assert LABELS["heldout_range_um"] != LABELS["residual_range_um"]
    assert fit1["heldout_range_um"] > rep1["residual_range_um"] * 1.05  # 2.678 vs 2.281 um
    assert fit1["range_before_um"] == rep1["range_before_um"]
    # and the old names are gone from every output
    for name, text in [*outputs["text"].items(), ("report summary.md", outputs["report_md"])]:
        lowered = text.lower()
        for old in ("range after", "range before→after", "rms after", "| ratio |"):
            assert old not in lowered, (name, old)
    for old in ("range_after_um", "range_reduction_pct", "rms_after_um", "model_ratio", "mean_abs_after_um"):
        assert old not in outputs["report"]["legs"][0]
    for old in ("within_pass_scatter_um", "pass_offset_scatter_um", "noise_floor_note"):
        assert old not in outputs["diagnosis"]["legs"]["1"]
    assert "range_after_um" not in json.loads(outputs["model_path"].read_text())["legs"]["1"]["stats"]


def _fit_table(text: str) -> dict[str, str]:
    """Leg 1's row of `station fit`'s table: printed name -> printed value."""
    lines = text.splitlines()
    header = next(line for line in lines if line.startswith("leg "))
    row = next(line for line in lines if line.strip().startswith("1 "))
    names = re.split(r"\s{2,}", header.strip())
    values = re.split(r"\s{2,}", row.strip())
    return dict(zip(names, values))


def _number(text: str) -> str:
    return re.match(r"-?[\d.]+", text.strip()).group(0)


def test_every_name_printed_by_two_commands_shows_one_value(outputs):
    """What an engineer reads: leg 1's figures as printed (3 decimals) by fit, diagnose, report
    (stdout and summary.md): one printed value per printed name."""
    printed: dict[str, dict[str, str]] = {}

    def add(cmd: str, name: str, value: str) -> None:
        printed.setdefault(name, {})[cmd] = _number(value)

    for name, value in _fit_table(outputs["text"]["fit"]).items():
        if name in ("leg", "terms"):
            continue
        add("fit", "ideal held-out ratio" if name == "(ideal)" else name, value)
    leg1 = outputs["text"]["diagnose"].split("LEG 1:")[1].split("LEG 2:")[0]
    for name in ("noise floor", "repeat scatter after effects", "twin held-out RMS"):
        add("diagnose", name, re.search(re.escape(name) + r" ([-\d.]+) um", leg1).group(1))
    rep = next(line for line in outputs["text"]["report"].splitlines() if line.startswith("leg 1: "))
    for name in ("range before", "residual range", "residual range reduction", "RMS before", "residual RMS"):
        add("report", name, re.search(r"(?:^|[ (;,])" + re.escape(name) + r" ([-\d.]+)", rep[len("leg 1:"):]).group(1))
    md = outputs["report_md"].splitlines()
    header = next(line for line in md if line.startswith("| leg | points |"))
    row = next(line for line in md if line.startswith("| 1 |"))
    for name, value in zip(header.strip("|").split("|"), row.strip("|").split("|")):
        name = name.strip().removesuffix(" (um)")
        if name in ("leg", "points", "cycles", "reversal"):
            continue
        # the model the report compensates with is the one station fit made of this recording
        add("report.md", name.removeprefix("model "), value)
    assert {"fit", "diagnose", "report.md"} <= set(printed["noise floor"])
    assert {"fit", "report", "report.md"} <= set(printed["range before"])
    assert {"fit", "report.md"} <= set(printed["held-out RMS"]) and {"fit", "report.md"} <= set(printed["held-out ratio"])
    for name, by in printed.items():
        assert len(set(by.values())) == 1, f"{name!r} printed as {by}"
    # every printed name is a named figure, and the two pairs are apart
    labels = set(LABELS.values()) | {"twin held-out RMS"}
    assert set(printed) <= labels, set(printed) - labels
    assert printed["noise floor"]["diagnose"] != printed["repeat scatter after effects"]["diagnose"]
    assert printed["held-out range"]["fit"] != printed["residual range"]["report"]


def test_iso230_values_have_the_same_names_in_report_and_iso230(outputs):
    md = outputs["report_md"]
    for key in "EMABR":
        assert f"{key}: {MEANINGS[key]}" in md
        assert MEANINGS[key] in outputs["text"]["iso230"]


def test_names_are_unique_and_documented():
    assert len(set(LABELS.values())) == len(LABELS)
    doc = FIGURES_DOC.read_text()
    for key, name in LABELS.items():
        assert f"`{key}`" in doc and name in doc, key


def test_a_model_file_with_the_old_range_key_still_loads(outputs, tmp_path):
    doc = json.loads(outputs["model_path"].read_text())
    for leg in doc["legs"].values():
        leg["stats"]["range_after_um"] = leg["stats"].pop("heldout_range_um")
    doc.pop("integrity")  # files from before the rename were written before the integrity record too
    old = tmp_path / "old.json"
    old.write_text(json.dumps(doc))
    model = load_model(old)
    for leg, lf in model.legs.items():
        assert lf.stats.heldout_range_um == outputs["model"].legs[leg].stats.heldout_range_um
    save_model(model, tmp_path / "again.json", str(SAMPLE), doc["source"]["sha256"])
    assert "heldout_range_um" in json.loads((tmp_path / "again.json").read_text())["legs"]["1"]["stats"]


def test_the_results_page_shows_the_commands_figures_on_their_basis(outputs, tmp_path):
    """The terminal UI's Results page on the sample: on the raw error (`t`) every figure it shows
    is the one `station fit --raw` and `station iso230 --raw` give above; on its default basis
    (normalised to 20 degC) the one `station fit` and `station iso230` give without --raw."""
    import asyncio
    import contextlib
    import io

    from textual.widgets import DataTable, Input

    from station.services.config import StationConfig
    from station.tui.app import StationApp

    normalised = {}
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["fit", str(SAMPLE), "--out", str(tmp_path / "model.json")]) == 0
        assert main(["iso230", str(SAMPLE), "--json", str(tmp_path / "iso230.json")]) == 0
    normalised["model"] = load_model(tmp_path / "model.json")
    normalised["iso230"] = json.loads((tmp_path / "iso230.json").read_text())
    assert normalised["model"].options["error_basis"]["normalised"]
    # the bases differ on the sample (its legs warm by about 0.3 K): the page cannot pass both by chance
    assert all(f"{normalised['iso230']['legs'][k]['E']:.3f}" != f"{outputs['iso230']['legs'][k]['E']:.3f}"
               for k in normalised["iso230"]["legs"])

    def check(app, cli) -> int:
        table = app.screen.query_one("#results-table", DataTable)
        labels = [str(c.label) for c in table.columns.values()]
        compared = 0
        for i in range(table.row_count):
            row = dict(zip(labels, table.get_row_at(i)))
            leg = int(row["Leg"])
            s = cli["model"].legs[leg].stats
            assert row["Noise floor"] == f"{s.noise_floor_um:.3f}" and row["Held-out RMS"] == f"{s.heldout_rms_um:.3f}"
            assert row["Held-out ratio"] == f"{s.heldout_ratio:.2f}"
            for name in "AEMBR":
                assert row[name].split("\n")[0] == f"{cli['iso230']['legs'][str(leg)][name]:.3f}", (leg, name)
            compared += 1
        return compared

    async def run() -> None:
        cfg = StationConfig(operator="test")
        cfg.recordings_dir = str(tmp_path / "runs")
        app = StationApp(cfg, autoconnect=False)
        async with app.run_test(size=(200, 50)) as pilot:
            await pilot.press("f3")
            app.screen.query_one("#session-path", Input).value = str(SAMPLE)
            await pilot.click("#session-open")
            for _ in range(6000):
                if app.analysis is not None:
                    break
                await pilot.pause(0.05)
            assert app.analysis is not None and not app.analysis.raw
            assert check(app, normalised) == 6
            await pilot.press("t")
            for _ in range(6000):
                if app.analysis.raw:
                    break
                await pilot.pause(0.05)
            assert app.analysis.raw
            assert check(app, outputs) == 6  # the --raw outputs of the fixture

    asyncio.run(run())


def _run(argv) -> str:
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(argv) == 0, argv
    return buf.getvalue()


@pytest.fixture(scope="module")
def default_basis(tmp_path_factory):
    """fit, iso230 and report on the sample without --raw (normalised to 20 degC)."""
    tmp = tmp_path_factory.mktemp("default-basis")
    text = {
        "fit": _run(["fit", str(SAMPLE), "--out", str(tmp / "model.json")]),
        "iso230": _run(["iso230", str(SAMPLE), "--json", str(tmp / "iso230.json")]),
        "report": _run(["report", str(SAMPLE), "--out", str(tmp / "report")]),
    }
    return {"tmp": tmp, "text": text, "model": load_model(tmp / "model.json"),
            "iso230": json.loads((tmp / "iso230.json").read_text()),
            "report": json.loads((tmp / "report" / "summary.json").read_text()),
            "report_md": (tmp / "report" / "summary.md").read_text(),
            "report_iso": json.loads((tmp / "report" / "iso230-2.json").read_text())}


def _basis_line(text: str) -> str:
    """The first line that is not a warning (the report warns first when the laser's calibration
    is not traceable: docs/session-schema.md, identity): the error basis the command used."""
    return next(line for line in text.splitlines() if not line.startswith("warning:"))


def test_report_agrees_with_fit_and_iso230_on_the_default_basis(default_basis, outputs):
    """`station report` without --model or --raw fits, plots and sums up the error normalised to
    20 degC, as `station fit` and `station iso230` do: every shared figure has one value, and it
    differs from the raw one (the sample's legs were not at 20 degC: the comparison can fail)."""
    d = default_basis
    rep = d["report"]
    assert rep["error_basis"]["basis"] == "normalised" and rep["error_basis"]["normalised"] is True
    assert d["report_iso"]["error_basis"]["basis"] == "normalised"
    assert "Error basis: **normalised**" in d["report_md"]
    assert _basis_line(d["text"]["report"]) == _basis_line(d["text"]["fit"])
    assert _basis_line(d["text"]["report"]).startswith("error: normalised to 20 degC")
    raw_rows = {row["leg"]: row for row in outputs["report"]["legs"]}
    assert outputs["report"]["error_basis"]["basis"] == "raw"
    differs = 0
    for row in rep["legs"]:
        leg = row["leg"]
        s = d["model"].legs[leg].stats
        for mine, theirs in (("range_before_um", s.range_before_um), ("noise_floor_um", s.noise_floor_um),
                             ("model_heldout_rms_um", s.heldout_rms_um), ("model_heldout_ratio", s.heldout_ratio)):
            assert row[mine] == pytest.approx(theirs, rel=1e-12, abs=1e-12), (leg, mine)
        iso = d["iso230"]["legs"][str(leg)]
        for name in VALUE_NAMES:
            assert row["iso230_2"]["before"][name] == pytest.approx(iso[name], rel=1e-12, abs=1e-12), (leg, name)
            assert d["report_iso"]["legs"][str(leg)]["values"][name]["value_um"] == pytest.approx(
                iso[name], rel=1e-12, abs=1e-12), (leg, name)
        differs += abs(row["range_before_um"] - raw_rows[leg]["range_before_um"]) > 1e-3
    assert differs >= 1


def test_report_with_a_model_uses_the_models_basis(default_basis, outputs, tmp_path, capsys):
    """--model: the report analyses the error the model was fitted to (its error_basis); --raw with
    a normalised model is refused, naming the model and what to do, and nothing is written."""
    d = default_basis
    out = tmp_path / "norm"
    _run(["report", str(SAMPLE), "--out", str(out), "--model", str(d["tmp"] / "model.json")])
    s = json.loads((out / "summary.json").read_text())
    assert s["error_basis"]["basis"] == "normalised"
    for row, ref in zip(s["legs"], d["report"]["legs"]):  # the same model, fitted by station fit: the same figures
        assert row["residual_rms_um"] == pytest.approx(ref["residual_rms_um"], rel=1e-9, abs=1e-9)
        assert row["range_before_um"] == pytest.approx(ref["range_before_um"], rel=1e-12, abs=1e-12)
    raw_out = tmp_path / "raw"
    text = _run(["report", str(SAMPLE), "--out", str(raw_out), "--model", str(outputs["model_path"])])
    assert _basis_line(text) == "error: raw, not normalised to 20 degC (--raw)"  # as station fit --raw said
    s = json.loads((raw_out / "summary.json").read_text())
    assert s["error_basis"]["basis"] == "raw"
    assert json.loads((raw_out / "iso230-2.json").read_text())["error_basis"]["basis"] == "raw"
    for row, ref in zip(s["legs"], outputs["report"]["legs"]):
        assert row["residual_rms_um"] == pytest.approx(ref["residual_rms_um"], rel=1e-9, abs=1e-9)
    capsys.readouterr()
    refused = tmp_path / "refused"
    assert main(["report", str(SAMPLE), "--out", str(refused), "--model", str(d["tmp"] / "model.json"), "--raw"]) != 0
    err = capsys.readouterr().err
    assert "model.json" in err and "normalised to 20 degC" in err and "--raw" in err and "Traceback" not in err
    assert not refused.exists()
