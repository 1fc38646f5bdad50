"""Fixtures of the web view tests: a SQLite catalog holding the known fleet (tests/web/fleet.py),
written through the catalog's own API, a certificate and tolerances beside it."""

from __future__ import annotations

import pytest

from station.catalog.store import Catalog
from station.web.app import WebSettings, create_app
from station.web.engine import open_readonly
from station.web.extensions import decision_tolerances_of, tolerances_of
from tests.web import fleet


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
                           where=f"catalog: {url}", page_size=page_size)
    return create_app(engine, settings), engine
