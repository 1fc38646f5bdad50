"""The web view in process (FastAPI TestClient): pages, filters, plots' points, 400/404 pages,
read-only, on a SQLite catalog filled through the catalog's API (tests/web/fleet.py)."""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient

from station.catalog import db
from tests.web import fleet
from tests.web.conftest import web_app


@pytest.fixture(scope="module")
def client(fleet_dir):
    app, engine = web_app(db.sqlite_url(fleet_dir / "catalog.sqlite"), fleet_dir, page_size=2)
    with TestClient(app, raise_server_exceptions=False) as c:
        yield c
    engine.dispose()


def serials(html: str) -> list[str]:
    return re.findall(r'<tr class="leg"><td><a href="/leg/[^"]+">([^<]+)</a>', html)


def points(html: str, figure_id: str) -> int:
    block = re.search(rf'<figure id="{figure_id}">(.*?)</figure>', html, re.S)
    assert block, figure_id
    return len(re.findall(r'<circle class="pt ', block.group(1)))


def all_fleet(client, **params) -> list[str]:
    out, page = [], 1
    while True:
        r = client.get("/", params={**params, "page": page})
        if r.status_code == 404:
            return out
        assert r.status_code == 200, r.text
        out += serials(r.text)
        page += 1


def test_fleet_pages_and_filters(client):
    assert all_fleet(client) == sorted(fleet.TYPES)
    assert len(serials(client.get("/").text)) == 2  # page size 2
    assert set(all_fleet(client, type="L450")) == {"HX-0004", "HX-0005"}
    assert set(all_fleet(client, station="ST-B")) == {"HX-0001", "HX-0002", "HX-0004"}
    assert set(all_fleet(client, since="2025-01-01")) == {"HX-0001", "HX-0004"}
    assert set(all_fleet(client, until="2024-12-31")) == {"HX-0002", "HX-0003"}
    assert set(all_fleet(client, due="2025-06-01")) == fleet.EXPECT["due_by_2025_06_01"]
    text = client.get("/", params={"type": "L300"}).text
    assert '<span id="total">3</span>' in text and 'id="next"' in text and "type=L300&amp;page=2" in text


def test_fleet_decision_filter(client):
    decided = fleet.EXPECT["decisions"]
    for key, label in (("conforming", "conforms"), ("not-conforming", "does not conform"),
                       ("undecided", "cannot decide"), ("no-tolerance", "no tolerance stated")):
        assert all_fleet(client, decision=key) == sorted(s for s, d in decided.items() if d == label), key
    assert all_fleet(client, decision="") == sorted(fleet.TYPES)
    html = client.get("/", params={"decision": "undecided"}).text
    assert '<td class="decision">cannot decide</td>' in html and '<option value="undecided" selected>' in html


@pytest.mark.parametrize("query, what", [
    ({"since": "2025-13-01"}, "since='2025-13-01': not a date"),
    ({"until": "yesterday"}, "until='yesterday': not a date"),
    ({"due": "soon"}, "due='soon': not a date"),
    ({"type": "L999"}, "type='L999': unknown type; known: L300, L450"),
    ({"station": "ST-Z"}, "unknown station"),
    ({"page": "-1"}, "page='-1': give a page number"),
    ({"page": "two"}, "page='two'"),
    ({"decision": "ok"}, "decision='ok': unknown decision; known: conforming, not-conforming, undecided, no-tolerance"),
])
def test_bad_queries_are_400_pages(client, query, what):
    r = client.get("/", params=query)
    assert r.status_code == 400
    assert r.headers["content-type"].startswith("text/html")
    assert what.replace("'", "&#39;") in r.text and "Traceback" not in r.text


def test_unknown_things_are_404_pages(client):
    for path, what in [("/leg/HX-9999", "no leg with serial"), ("/?page=99", "there are 3 page(s)"),
                       ("/nowhere", "nothing at /nowhere"), ("/leg/HX-0001/certificate/x.pdf", "no certificate"),
                       ("/compare?serial=HX-0002", "no completed as-found calibrations at more than one station")]:
        r = client.get(path)
        assert r.status_code == 404, path
        assert what.replace("'", "&#39;") in r.text and "<h1 class=\"error\">404" in r.text
    r = client.get("/charts?type=nope")
    assert r.status_code == 400


def test_read_only(client):
    for method in ("post", "put", "delete"):
        r = getattr(client, method)("/")
        assert r.status_code == 405 and "read-only" in r.text


def test_leg_page(client):
    r = client.get("/leg/HX-0001")
    assert r.status_code == 200
    t = r.text
    for f in ("E", "B", "R"):
        assert points(t, f"plot-{f}") == fleet.EXPECT["calibrations"]["HX-0001"]
        assert t.count(f'class="hline hline-tol"') == 3  # E, B, R limits of L300
    assert fleet.TABLE_SHA in t and "D1 (127.0.0.1:5020 unit 1)" in t and "/runs/tables/HX-0001.csv" in t
    assert "ratio 1.20" in t and "C-2025-0001" in t
    t4 = client.get("/leg/HX-0004").text
    assert points(t4, "plot-E") == 2 and "hline-tol" not in t4 and "No tolerance stated for L450" in t4
    t5 = client.get("/leg/HX-0005").text
    assert points(t5, "plot-E") == 0 and "Never calibrated" in t5 and "No certificate issued" in t5


def test_certificate_download(client, fleet_dir):
    r = client.get("/leg/HX-0001/certificate/C-2025-0001_r1.pdf")
    assert r.status_code == 200 and r.headers["content-type"] == "application/pdf"
    assert r.content.startswith(b"%PDF") and r.content == (fleet_dir / "certificates/C-2025-0001_r1.pdf").read_bytes()
    assert client.get("/leg/HX-0002/certificate/C-2025-0001_r1.pdf").status_code == 404  # another leg's


def test_control_charts(client):
    t = client.get("/charts", params={"type": "L300"}).text
    for f in ("E", "B", "R"):
        assert points(t, f"chart-{f}") == fleet.EXPECT["cal_L300"]
    es = [8.0, 8.6, 9.1, 12.1, 6.0, 6.5, 7.0]
    import statistics
    mean, s = statistics.fmean(es), statistics.stdev(es)
    assert f"{mean:.3f}" in t and f"{(12.0 - mean) / (3 * s):.2f}" in t
    t450 = client.get("/charts", params={"type": "L450"}).text
    assert points(t450, "chart-E") == fleet.EXPECT["cal_L450"] and "no Cpk: no tolerance" in t450


def test_station_comparison(client):
    t = client.get("/compare").text
    assert "2 leg(s) with as-found calibrations at more than one station" in t
    flagged = set(re.findall(r'<tr class="pair flagged" data-serial="([^"]+)"', t))
    assert flagged == {s for s, f in fleet.EXPECT["compared"].items() if f}
    en = (12.1 - 9.1) / (0.5 ** 2 + 0.5 ** 2) ** 0.5
    assert f"{-en:+.2f}" in t  # ST-A - ST-B
    one = client.get("/compare", params={"serial": "HX-0004"}).text
    assert points(one, "cmp-plot-E") == 2 and "pair flagged" not in one and "class=\"pair\"" in one


def test_command_missing_catalog_is_one_line(tmp_path, capsys):
    from station.cli import main

    assert main(["web", "--catalog", str(tmp_path / "none.sqlite")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "none.sqlite: no such file" in err and "station catalog sync" in err
    assert not (tmp_path / "none.sqlite").exists()  # nothing created


def test_readonly_engine_refuses_writes(fleet_dir):
    import sqlalchemy as sa

    from station.web.engine import open_readonly

    engine = open_readonly(str(db.sqlite_url(fleet_dir / "catalog.sqlite")))
    with pytest.raises(sa.exc.OperationalError, match="readonly"):
        with engine.begin() as conn:
            conn.exec_driver_sql("DELETE FROM legs")
    engine.dispose()


def test_tolerances_are_the_configs_as_left_limits(tmp_path):
    from procedures.vocabulary import InputError
    from station.web.extensions import tolerances_of

    p = tmp_path / "s.toml"
    p.write_text('[tolerances.L300]\nE_um = 12\nB_um = 3\n[tolerances.L300.as_left]\nE_um = 10.5\n')
    assert tolerances_of(p) == {"L300": {"E": 10.5, "B": 3.0}} and tolerances_of(None) == {}
    p.write_text('[tolerances.L300]\nE_um = -1\n')
    with pytest.raises(InputError, match=r"s.toml: \[tolerances.L300\] E_um"):
        tolerances_of(p)


def test_certificates_found_by_serial_in_the_certificate_index(tmp_path):
    import json

    from station.web.extensions import certificates_of

    fleet.write_certificate(tmp_path, "HX-0001", "C-1")
    d = tmp_path / "certificates"
    (d / "bad.index.json").write_text("{not json")
    (d / "escape.index.json").write_text(json.dumps({"report_no": "E", "revisions": [
        {"revision": 1, "status": "issued", "serial": "HX-0001", "pdf": "../C-1_r1.pdf"}]}))
    (d / "missing.index.json").write_text(json.dumps({"report_no": "M", "revisions": [
        {"revision": 1, "status": "issued", "serial": "HX-0001", "pdf": "gone.pdf"}]}))
    found = certificates_of(tmp_path, "HX-0001")
    assert [c.pdf_name for c in found] == ["C-1_r1.pdf"] and found[0].number == "C-1" and not found[0].superseded
    assert certificates_of(tmp_path, "HX-0002") == [] and certificates_of(tmp_path / "nowhere", "HX-0001") == []
