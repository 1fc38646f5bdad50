"""Fixtures of the web view tests: a SQLite catalog holding the known fleet (tests/web/fleet.py),
written through the catalog's own API, a certificate and tolerances beside it."""

from __future__ import annotations

import os

import pytest

from station.catalog.store import Catalog
from station.web.app import WebSettings, create_app
from station.web.engine import open_readonly, what_to_check
from station.web.extensions import decision_tolerances_of, tolerances_of
from tests.web import fleet
from tests.web.browser import CHROMIUM, DRIVER, chromium


def need_browser() -> None:
    """Skip (naming why) without Chromium and chromedriver; under CI=true a failure."""
    if CHROMIUM and DRIVER:
        return
    reason = "headless Chromium not installed: apt-get install chromium chromium-driver"
    if os.environ.get("CI") == "true":
        pytest.fail(reason)
    pytest.skip(reason)


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    """One headless Chromium per test module."""
    need_browser()
    downloads = tmp_path_factory.mktemp("downloads")
    driver = chromium(tmp_path_factory.mktemp("chromium-profile"), downloads)
    driver.set_page_load_timeout(20)
    driver.downloads = downloads
    yield driver
    driver.quit()


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet")
    cat = Catalog(local=d / "catalog.sqlite", station_id="ST-X")
    cat.ingest(fleet.records())
    cat.close()
    fleet.write_certificate(d)
    (d / "station.toml").write_text(fleet.TOLERANCES_TOML)
    return d


def web_app(url: str, runs_dir, page_size: int = 2):
    """The app over the catalog at `url`, read-only, with the fleet's tolerances; small pages so
    the few legs span several."""
    engine = open_readonly(url)
    settings = WebSettings(tolerances=tolerances_of(runs_dir / "station.toml"), runs_dir=runs_dir,
                           decision_tolerances=decision_tolerances_of(runs_dir / "station.toml"),
                           where=f"catalog: {url}", page_size=page_size, check_hint=what_to_check(url))
    return create_app(engine, settings), engine
