"""What a reviewer of hundreds of legs uses on the fleet page (issue 33.2): counts and yield per
verdict, a serial search, sorting, CSV export of what the filters keep, and long serials that wrap
in their cell instead of pushing the columns off the page (read in Chromium at 900 px wide).

A catalog of 8 legs written through the catalog API, each session decided at ingest
(readers.decide_legs) against E 6 um as found: 5 conform, 2 do not, 1 cannot decide.
"""

from __future__ import annotations

import csv
import io
import re

import pytest

from procedures.reporting.decision import Tolerance
from station.catalog import db
from station.catalog.readers import Rec, decide_legs
from station.catalog.store import Catalog
from station.web.app import WebSettings, create_app
from station.web.engine import open_readonly

LONG = "HX-" + "7" * 61  # 64 characters: the longest serial the grammar allows
# serial -> E um (U 0.2): <= 5.8 conforms, > 6.2 does not, between cannot decide
LEGS = {"HX-0001": 2.0, "HX-0002": 9.0, "HX-0003": 3.0, "HX-0010": 6.0, "HX-0011": 1.0, "AB-0001": 7.5,
        "AB-0002": 4.0, LONG: 5.0}


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    d = tmp_path_factory.mktemp("review")
    tol = {"HX300": Tolerance("HX300", {"E": 6.0}, {"E": 3.0})}
    recs = []
    for i, (serial, e) in enumerate(LEGS.items()):
        rec = Rec(kind="session", key=f"k{i}", time_utc=f"2026-01-{i + 1:02d}T00:00:00Z", station_id="ST-A",
                  outcome="completed", path=f"/r/{i}.h5", sha256=f"k{i}")
        rec.legs[1] = {"leg_serial": serial, "E_um": e, "E_U_um": 0.2, "B_um": 1.0, "B_U_um": 0.1}
        rec.leg_info[serial] = {"leg_type": "=HX300" if serial == "AB-0002" else "HX300", "part_number": None,
                                "screw_lot": None}
        recs.append(decide_legs(rec, tol))
    cat = Catalog(local=d / "c.sqlite", station_id="ST-A")
    cat.ingest(recs)
    cat.close()
    engine = open_readonly(db.sqlite_url(d / "c.sqlite"))
    yield create_app(engine, WebSettings(decision_tolerances=tol, page_size=50))
    engine.dispose()


@pytest.fixture(scope="module")
def client(app):
    from fastapi.testclient import TestClient

    with TestClient(app) as c:
        yield c


def listed(html: str) -> list[str]:
    return re.findall(r'<tr class="leg"><td><a href="/leg/[^"]+">([^<]+)</a>', html)


def test_counts_and_yield_per_verdict(client):
    t = client.get("/").text
    counts = dict(re.findall(r'data-decision="([a-z-]+)">.*?<td class="num">(\d+)</td>', t))
    # AB-0002's type "=HX300" has no tolerance
    assert counts == {"conforming": "4", "not-conforming": "2", "undecided": "1", "no-tolerance": "1"}
    assert "Yield (conforming legs among those with a tolerance): 57.1 % (4 of 7)" in t


def test_serial_search_and_sorting(client):
    assert listed(client.get("/", params={"serial": "hx-001"}).text) == ["HX-0010", "HX-0011"]
    by_e = listed(client.get("/", params={"sort": "-E"}).text)
    assert by_e == sorted(LEGS, key=LEGS.get, reverse=True)
    assert listed(client.get("/", params={"sort": "serial"}).text) == sorted(LEGS)
    r = client.get("/", params={"sort": "colour"})
    assert r.status_code == 400 and "unknown sort" in r.text
    assert client.get("/", params={"serial": "x" * 65}).status_code == 400


def test_csv_export_holds_every_leg_the_filters_keep(client):
    r = client.get("/fleet.csv", params={"decision": "conforming", "sort": "E"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    assert 'filename="fleet.csv"' in r.headers["content-disposition"]
    rows = list(csv.DictReader(io.StringIO(r.text)))
    assert [x["serial"] for x in rows] == ["HX-0011", "HX-0001", "HX-0003", LONG]
    assert {x["decision"] for x in rows} == {"conforms"} and rows[0]["E_um"] == "1.0000"
    everything = list(csv.DictReader(io.StringIO(client.get("/fleet.csv").text)))
    # a type beginning with "=" is quoted so a spreadsheet does not run it as a formula
    assert len(everything) == len(LEGS) and {x["leg_type"] for x in everything} == {"HX300", "'=HX300"}


def test_long_serial_never_pushes_columns_off_the_page(app, browser):
    from tests.web.browser import Server

    server = Server(app)
    size = browser.get_window_size()
    try:
        browser.set_window_size(900, 900)
        browser.get(server.url + "/?sort=-serial")
        facts = browser.execute_script("""
            const t = document.getElementById('legs');
            const cell = t.querySelector('tbody tr td');
            return {page: document.documentElement.scrollWidth, view: document.documentElement.clientWidth,
                    right: t.getBoundingClientRect().right, first: cell.textContent.trim()};
        """)
        assert facts["first"] == LONG  # the long one is on the page, sorted first
        assert facts["page"] <= facts["view"] and facts["right"] <= facts["view"], facts
    finally:
        browser.set_window_size(size["width"], size["height"])
        server.stop()
