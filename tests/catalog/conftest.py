"""Fixtures of the catalog tests: a PostgreSQL cluster for the session (tests/pg.py), catalog
writes turned on for these tests (tests/conftest.py turns them off elsewhere)."""

from __future__ import annotations

import pytest

from tests.pg import remove, start_cluster


@pytest.fixture(scope="session")
def pg_cluster():
    cluster = start_cluster()
    yield cluster
    remove(cluster)


@pytest.fixture
def pg_url(pg_cluster) -> str:
    """A fresh database of the session's cluster."""
    return pg_cluster.new_database()


@pytest.fixture(autouse=True)
def catalog_on(monkeypatch):
    monkeypatch.setenv("STATION_CATALOG", "on")
