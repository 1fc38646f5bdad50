"""`/certificates` of the fleet view: every certificate revision in the catalog, wherever its PDF
was written (station.catalog.certificates.issued): number, revision, draft / approved /
superseded, the leg's serial (a link to its page), dates, who approved and the PDF's path.
`/certificates/pdf/SHA256` downloads one (an auditor, as the leg page's downloads) when the file
is on this machine with the sha256 the catalog holds. A module of its own so the certificate
work does not edit the fleet pages' routes."""

from __future__ import annotations

from typing import Callable

from fastapi import FastAPI, Request
from fastapi.responses import FileResponse, HTMLResponse
from sqlalchemy.engine import Engine

from station.services.serials import is_serial


def add_routes(app: FastAPI, engine: Engine, page: Callable[..., HTMLResponse],
               refuse: Callable[[int, str], Exception]) -> None:
    """Add GET /certificates[?serial=S] and /certificates/pdf/SHA256 to `app`; `page(request,
    template, **context)` renders, `refuse(status, message)` is the exception the app answers
    with an error page."""
    import hashlib  # noqa: PLC0415
    import re  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    import sqlalchemy as sa  # noqa: PLC0415

    from station.catalog.certificates import KIND, issued  # noqa: PLC0415
    from station.catalog.models import Record  # noqa: PLC0415

    @app.get("/certificates/pdf/{sha256}")
    def certificate_pdf(request: Request, sha256: str):
        if not re.fullmatch(r"[0-9a-f]{64}", sha256):
            raise refuse(400, f"{sha256[:80]!r} is not a sha256 (64 hex digits)")
        role = getattr(request.state, "web_role", None)
        if role is not None and role != "auditor":
            raise refuse(403, f"certificates are downloaded by an auditor; {request.state.web_user} is a {role} "
                              "([web.users.NAME] role in the station config)")
        with engine.connect() as conn:
            path = conn.execute(sa.select(Record.path).where(Record.kind == KIND, Record.sha256 == sha256)).scalar()
        if path is None:
            raise refuse(404, f"no certificate with sha256 {sha256[:16]}... in the catalog")
        p = Path(path)
        # the catalog's path may name another station's disk; serve only the very file it indexed
        if not p.is_file() or hashlib.sha256(p.read_bytes()).hexdigest() != sha256:
            raise refuse(404, f"{p.name} is not on this machine as indexed (written at {path}); ask its station")
        return FileResponse(p, media_type="application/pdf", filename=p.name)

    @app.get("/certificates", response_class=HTMLResponse)
    def certificates(request: Request, serial: str | None = None):
        if serial and not is_serial(serial):
            raise refuse(400, f"serial={serial[:80]!r} is not a serial number")
        rows = issued(engine, serial or None)
        return page(request, "certificates.html", rows=rows, serial=serial or "")
