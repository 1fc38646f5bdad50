"""`/certificates` of the fleet view: every certificate revision in the catalog, wherever its PDF
was written (station.catalog.certificates.issued): number, revision, draft / approved /
superseded, the leg's serial (a link to its page), dates, who approved and the PDF's path. A
module of its own so the certificate work does not edit the fleet pages' routes."""

from __future__ import annotations

from typing import Callable

from fastapi import FastAPI, Request
from fastapi.responses import HTMLResponse
from sqlalchemy.engine import Engine

from station.services.serials import is_serial


def add_routes(app: FastAPI, engine: Engine, page: Callable[..., HTMLResponse], bad_request: Callable[[str], Exception]) -> None:
    """Add GET /certificates[?serial=S] to `app`; `page(request, template, **context)` renders,
    `bad_request(message)` is the exception the app answers with a 400 page."""
    from station.catalog.certificates import issued  # noqa: PLC0415

    @app.get("/certificates", response_class=HTMLResponse)
    def certificates(request: Request, serial: str | None = None):
        if serial and not is_serial(serial):
            raise bad_request(f"serial={serial[:80]!r} is not a serial number")
        rows = issued(engine, serial or None)
        return page(request, "certificates.html", rows=rows, serial=serial or "")
