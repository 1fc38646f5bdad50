"""The web view in a real browser: `station web`'s app served by uvicorn on 127.0.0.1 (a free
port, a thread), driven by selenium through Debian's headless Chromium and chromedriver. Every
page loads without a console error, filters change what is listed, each plot holds the right
number of points, a certificate downloads as a valid PDF. Screenshots go to the test's tmp dir
(and to $STATION_WEB_SHOTS when set). Once on SQLite, once on a real PostgreSQL (tests/pg.py).

Skipped (naming why) without chromium/chromedriver, never under CI=true (.ci/run installs them).
"""

from __future__ import annotations

import os
import re
import shutil
import time
from pathlib import Path

import pytest

from station.catalog import db
from station.catalog.store import write_recs
from tests.web import fleet
from tests.web.browser import Server
from tests.web.conftest import need_browser as _need_browser, web_app


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def site(request, fleet_dir):
    """(base URL, backend) of a server over the known fleet in a SQLite or a PostgreSQL catalog."""
    _need_browser()
    cluster = None
    if request.param == "sqlite":
        url = db.sqlite_url(fleet_dir / "catalog.sqlite")
    else:
        from tests.pg import remove, start_cluster

        cluster = start_cluster()
        request.addfinalizer(lambda: remove(cluster))
        url = cluster.new_database()
        engine = db.open_engine(url)
        with engine.begin() as conn:
            write_recs(conn, fleet.records(), "ST-X", queue=False)
        engine.dispose()
    app, engine = web_app(url, fleet_dir, page_size=2)
    if request.param == "postgresql":  # opened read-only: no page could write
        import sqlalchemy as sa

        with pytest.raises(sa.exc.InternalError, match="read-only transaction"):
            with engine.begin() as conn:
                conn.exec_driver_sql("DELETE FROM legs")
    server = Server(app)
    yield server.url, request.param
    server.stop()
    engine.dispose()


@pytest.fixture
def shoot(browser, tmp_path, site):
    """shoot(name): a screenshot in the test's tmp dir (and in $STATION_WEB_SHOTS)."""
    def take(name: str) -> Path:
        path = tmp_path / f"{site[1]}-{name}.png"
        browser.save_screenshot(str(path))
        if os.environ.get("STATION_WEB_SHOTS"):
            out = Path(os.environ["STATION_WEB_SHOTS"])
            out.mkdir(parents=True, exist_ok=True)
            shutil.copy(path, out / path.name)
        return path
    return take


def visit(browser, url: str) -> None:
    """Load `url`; no severe console entry (a failed resource, a script error) may follow."""
    browser.get_log("browser")  # drop what came before
    browser.get(url)
    severe = [e for e in browser.get_log("browser") if e.get("level") == "SEVERE"]
    assert not severe, f"{url}: console errors {severe}"


def count(browser, css: str) -> int:
    from selenium.webdriver.common.by import By

    return len(browser.find_elements(By.CSS_SELECTOR, css))


def listed(browser) -> list[str]:
    from selenium.webdriver.common.by import By

    return [e.text for e in browser.find_elements(By.CSS_SELECTOR, "#legs tr.leg td:first-child a")]


def click_and_wait(browser, element) -> None:
    """Click a link or button that loads a new page; return once it has."""
    from selenium.webdriver.support import expected_conditions as EC
    from selenium.webdriver.support.ui import WebDriverWait

    from selenium.common.exceptions import WebDriverException

    old = browser.find_element("tag name", "html")
    element.click()

    def replaced(driver) -> bool:
        try:
            return EC.staleness_of(old)(driver)
        except WebDriverException as exc:  # Chromium may say so instead of "stale" while the page swaps
            if "does not belong to the document" in str(exc):
                return True
            raise

    WebDriverWait(browser, 15).until(replaced)


def test_fleet_and_filters(browser, site, shoot):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    base, _ = site
    visit(browser, base + "/")
    assert listed(browser) == ["HX-0001", "HX-0002"] and browser.find_element(By.ID, "total").text == "5"
    shoot("fleet")
    Select(browser.find_element(By.ID, "f-type")).select_by_visible_text("L450")
    click_and_wait(browser, browser.find_element(By.ID, "f-apply"))
    assert listed(browser) == ["HX-0004", "HX-0005"] and browser.find_element(By.ID, "total").text == "2"
    assert not [e for e in browser.get_log("browser") if e.get("level") == "SEVERE"]
    shoot("fleet-type-L450")
    visit(browser, base + "/?due=2025-06-01")
    assert set(listed(browser)) == fleet.EXPECT["due_by_2025_06_01"]
    visit(browser, base + "/?type=L300")
    click_and_wait(browser, browser.find_element(By.ID, "next"))
    assert listed(browser) == ["HX-0003"]


def test_leg_page_plots_and_certificate(browser, site, shoot):
    from selenium.webdriver.common.by import By

    base, _ = site
    visit(browser, base + "/leg/HX-0001")
    n = fleet.EXPECT["calibrations"]["HX-0001"]
    for f in ("E", "B", "R"):
        assert count(browser, f"#plot-{f} circle.pt") == n
        assert count(browser, f"#plot-{f} line.ubar") == n
        assert count(browser, f"#plot-{f} line.hline-tol") == 1
    assert count(browser, "#pushes tr.push") == 1
    shoot("leg-HX-0001")
    for old in browser.downloads.iterdir():
        old.unlink()
    browser.find_element(By.CSS_SELECTOR, "#certificates a").click()
    target = browser.downloads / "C-2025-0001_r1.pdf"
    deadline = time.monotonic() + 15
    while not target.is_file() and time.monotonic() < deadline:
        time.sleep(0.05)
    data = target.read_bytes()
    assert data.startswith(b"%PDF") and data.rstrip().endswith(b"%%EOF")
    assert len(re.findall(rb"/Type\s*/Page(?![a-z])", data)) == 2  # the two pages written


def test_charts_compare_and_errors(browser, site, shoot):
    from selenium.webdriver.common.by import By

    base, _ = site
    visit(browser, base + "/charts?type=L300")
    for f in ("E", "B", "R"):
        assert count(browser, f"#chart-{f} circle.pt") == fleet.EXPECT["cal_L300"]
        assert count(browser, f"#chart-{f} line.hline-limit") == 2
    shoot("charts-L300")
    visit(browser, base + "/compare")
    flagged = {e.get_attribute("data-serial") for e in browser.find_elements(By.CSS_SELECTOR, "tr.pair.flagged")}
    assert flagged == {"HX-0001"}
    shoot("compare")
    visit(browser, base + "/compare?serial=HX-0001")
    assert count(browser, "#cmp-plot-E circle.pt") == 2
    shoot("compare-HX-0001")
    browser.get(base + "/leg/HX-9999")  # a 404 page: its status is a console entry, its text the message
    assert "404 Not found" in browser.find_element(By.TAG_NAME, "h1").text
    assert "no leg with serial 'HX-9999'" in browser.find_element(By.ID, "message").text
    shoot("404")
    browser.get(base + "/?since=2025-13-01")
    assert "400 Bad request" in browser.find_element(By.TAG_NAME, "h1").text
    shoot("400")


def test_fleet_decision_filter(browser, site, shoot):
    """Each decision filter value lists the legs whose latest session has that ISO 14253-1 verdict,
    and the table shows every leg's verdict."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    base, _ = site
    expected = fleet.EXPECT["decisions"]
    visit(browser, base + "/")
    rows = browser.find_elements(By.CSS_SELECTOR, "#legs tr.leg")
    shown = {r.find_element(By.CSS_SELECTOR, "td:first-child a").text: r.find_element(By.CSS_SELECTOR, "td.decision").text
             for r in rows}
    assert shown == {s: expected[s] for s in ("HX-0001", "HX-0002")}
    for label in ("conforms", "does not conform", "cannot decide", "no tolerance stated"):
        Select(browser.find_element(By.ID, "f-decision")).select_by_visible_text(label)
        click_and_wait(browser, browser.find_element(By.ID, "f-apply"))
        want = sorted(s for s, d in expected.items() if d == label)
        assert listed(browser) == want, label
        assert [e.text for e in browser.find_elements(By.CSS_SELECTOR, "#legs td.decision")] == [label] * len(want)
        assert browser.find_element(By.ID, "total").text == str(len(want))
        assert Select(browser.find_element(By.ID, "f-decision")).first_selected_option.text == label
        if label == "cannot decide":
            shoot("fleet-decision-undecided")
    Select(browser.find_element(By.ID, "f-decision")).select_by_visible_text("all")
    click_and_wait(browser, browser.find_element(By.ID, "f-apply"))
    assert browser.find_element(By.ID, "total").text == str(fleet.EXPECT["legs"])
    # combined with the type filter, and kept across pages
    visit(browser, base + "/?type=L300&decision=conforming")
    assert listed(browser) == ["HX-0002"]
    visit(browser, base + "/?type=L450&decision=conforming")
    assert listed(browser) == [] and browser.find_element(By.ID, "total").text == "0"
