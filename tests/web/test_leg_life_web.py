"""The leg's life of tests/station/test_leg_life.py (station A calibrates HX-0001, pushes, verifies;
station B calibrates it) seen by `station compare` and the web view (issue 33.2): a calibration
is never compared with a verification (the command refuses, exit 2, one line; the web pairs
sessions of one stage only), the web comparison flags nothing for this leg, and the leg page and
the control charts draw each stage against its own limit (read in real Chromium: the SVG's points
and lines, their stage, and the labels' boxes, which must not overlap).

The scenario runs once for the module (about 10 s, its fixture reused); one Chromium.
"""

from __future__ import annotations

import json

import pytest

from procedures.reporting.decision import Tolerance
from station.catalog import db
from station.web.app import WebSettings, create_app
from station.web.engine import open_readonly
from tests.station.test_leg_life import SERIAL, _Capture, life  # noqa: F401  (the module's scenario fixture)
from tests.web.browser import Server

pytestmark = pytest.mark.timeout(300)

# different limits as found and as left, so a point read against the other stage's limit shows
AS_FOUND = {"E": 12.0, "B": 5.0, "R": 6.0}
AS_LEFT = {"E": 6.0, "B": 3.0, "R": 4.0}


@pytest.fixture(scope="module")
def web(life):  # noqa: F811
    engine = open_readonly(db.sqlite_url(life["tmp"] / "shared.sqlite"))
    tol = {"HX300": Tolerance("HX300", dict(AS_FOUND), dict(AS_LEFT))}
    app = create_app(engine, WebSettings(decision_tolerances=tol, compare_window_days=90.0))
    yield app
    engine.dispose()


def test_compare_of_a_calibration_with_a_verification_is_refused(life, tmp_path):  # noqa: F811
    ra = life["tmp"] / "ST-A"
    cap = _Capture()
    rc = cap.run(["compare", ra / "cal.h5", ra / "ver.h5", "--out", tmp_path / "cmp"])
    lines = cap.err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "Traceback" not in cap.err, cap.err
    assert "cal.h5 is an as-found calibration but ver.h5 is an as-left verification" in lines[0]
    assert "same stage" in lines[0] and not (tmp_path / "cmp").exists()  # refused before anything is written


def test_web_comparison_pairs_calibrations_only_and_flags_nothing(life, web):  # noqa: F811
    from fastapi.testclient import TestClient

    from station.catalog import queries

    with TestClient(web) as client:
        t = client.get("/compare").text
        assert "1 leg(s) with as-found calibrations at more than one station" in t
        assert 'class="pair flagged"' not in t and "disagrees ⚑" not in t and t.count(">agrees<") == 2, t[t.find("<table"):]
        left = client.get("/compare", params={"stage": "as_left"}).text
        assert "0 leg(s) with as-left verifications at more than one station" in left  # only station A verified
        assert client.get("/compare", params={"stage": "nope"}).status_code == 400
    engine = open_readonly(db.sqlite_url(life["tmp"] / "shared.sqlite"))
    (item,), total = queries.compared_serials(engine, serial=SERIAL)
    engine.dispose()
    # each station's as-found calibration, not station A's later verification
    h = json.loads(life["history_json"][1])
    cal_times = {r["station_id"]: r["time_utc"] for r in h["rows"] if r["kind"] == "session" and r["stage"] == "as_found"}
    assert {s.station_id: s.time_utc for s in item.stations} == cal_times
    (pair,) = item.pairs
    assert pair.in_window and pair.days_apart < 1 and not pair.flagged
    assert all(v is not None and abs(v) <= 1 for v in pair.en.values()), pair.en


def _svg_facts(browser, figure_id: str) -> dict:
    """What the browser drew in one figure: points by stage, tolerance lines by stage, every
    reference line's value, and whether any two reference-line labels' boxes overlap."""
    return browser.execute_script("""
        const fig = document.getElementById(arguments[0]);
        const pts = {}; fig.querySelectorAll('circle.pt').forEach(c => {
            const s = c.dataset.stage; pts[s] = (pts[s] || 0) + 1; });
        const tol = {}; fig.querySelectorAll('line.hline-tol').forEach(l => {
            tol[l.dataset.stage || 'both'] = parseFloat(l.dataset.y); });
        const ys = [...fig.querySelectorAll('line.hline')].map(l => parseFloat(l.dataset.y));
        const boxes = [...fig.querySelectorAll('text.hlabel')].map(t => t.getBBox());
        let overlap = false;
        for (let i = 0; i < boxes.length; i++) for (let j = i + 1; j < boxes.length; j++) {
            const a = boxes[i], b = boxes[j];
            if (a.x < b.x + b.width && b.x < a.x + a.width && a.y < b.y + b.height && b.y < a.y + a.height) overlap = true;
        }
        const tips = [...fig.querySelectorAll('circle.pt > title')].map(t => t.textContent);
        return {pts, tol, ys, overlap, tips};
    """, figure_id)


def test_leg_page_and_charts_per_stage_with_their_own_limits(life, web, browser):  # noqa: F811
    from tests.web.test_browser import visit

    server = Server(web)
    try:
        visit(browser, f"{server.url}/leg/{SERIAL}")
        for f in ("E", "B", "R"):
            facts = _svg_facts(browser, f"plot-{f}")
            # two as-found calibrations (A, B), one as-left verification (A), each against its stage's limit
            assert facts["pts"] == {"as_found": 2, "as_left": 1}, facts
            assert facts["tol"] == {"as_found": AS_FOUND[f], "as_left": AS_LEFT[f]}, facts
            assert not facts["overlap"] and min(facts["ys"]) >= 0
            assert any("ST-B" in tip for tip in facts["tips"]) and all("µm" in tip for tip in facts["tips"])
        visit(browser, f"{server.url}/charts?type=HX300")
        for f in ("E", "B", "R"):
            found, left = _svg_facts(browser, f"chart-{f}"), _svg_facts(browser, f"chart-{f}-as_left")
            assert found["pts"] == {"as_found": 2} and found["tol"] == {"as_found": AS_FOUND[f]}, found
            assert left["pts"] == {"as_left": 1} and left["tol"] == {"as_left": AS_LEFT[f]}, left
            for facts in (found, left):  # no limit under 0 for a value that cannot be negative
                assert min(facts["ys"]) >= 0 and not facts["overlap"], facts
        from selenium.webdriver.common.by import By

        rows = {(r.get_attribute("data-stage"), r.get_attribute("data-figure")): r.text
                for r in browser.find_elements(By.CSS_SELECTOR, "#chart-stats tr.stat")}
        assert rows[("as_left", "E")].split()[3] == "1" and rows[("as_found", "E")].split()[3] == "2"  # n per stage
    finally:
        server.stop()


def test_web_per_target_en_is_what_station_compare_prints(life, web, tmp_path):  # noqa: F811
    """The leg's comparison page shows, target by target, both stations' mean deviations with
    their U and E_n: the figures `station compare` writes for the same two calibrations (one
    evaluation at ingest, one E_n formula), every row."""
    import re

    from fastapi.testclient import TestClient

    cap = _Capture()
    out = tmp_path / "cmp"
    assert cap.run(["compare", life["tmp"] / "ST-A" / "cal.h5", life["tmp"] / "ST-B" / "cal.h5", "--out", out]) == 0
    (pair,) = json.loads((out / "compare.json").read_text())["pairs"]
    with TestClient(web) as client:
        t = client.get("/compare", params={"serial": SERIAL}).text
    assert "Per target: ST-A − ST-B" in t and 'class="targets-missing"' not in t
    table = t[t.index('<table class="targets"'):]
    table = table[:table.index("</table>")]
    cells = [re.findall(r"<td[^>]*>([^<]*)", row) for row in re.findall(r'<tr class="target[^"]*">(.*?)</tr>', table)]
    assert len(cells) == pair["n_targets"] == len(pair["rows"]) > 10
    for web_row, r in zip(cells, pair["rows"]):
        assert web_row[0] == r["direction"] and float(web_row[1]) == pytest.approx(r["target_mm"], abs=1e-3)
        got = [float(c.replace(" ⚑", "")) for c in web_row[2:]]
        want = [r["x_a_um"], r["U_a_um"], r["x_b_um"], r["U_b_um"], r["d_um"], r["E_n"]]
        assert got == pytest.approx(want, abs=0.006), (web_row, r)
    assert f"at {pair['exceed']} of {pair['n_targets']} targets" in t
