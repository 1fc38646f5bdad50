"""The fleet web view (`station web`): a read-only FastAPI app over a catalog engine.

Pages: `/` the fleet (legs, filters, pages), `/leg/SERIAL` a leg's history with plots, tables
pushed and certificates, `/charts?type=T` control charts per leg type, `/compare` the station
comparison. GET only; every error is an HTML page (400 bad query, 404 unknown serial or page,
405 another method, 503 catalog unreachable naming what to check, 500 one line), never a traceback
nor a driver's message. Who may connect, and the security headers: station/web/access.py.
"""

from __future__ import annotations

import csv
import datetime as dt
import functools
import io
import logging
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote, urlencode

import sqlalchemy as sa

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, Response
from fastapi.staticfiles import StaticFiles
from fastapi.templating import Jinja2Templates
from sqlalchemy.engine import Engine
from starlette.exceptions import HTTPException as StarletteHTTPException

from procedures.io.recording.stage import AS_FOUND, AS_LEFT
from station.catalog.history import history, parse_utc
from station.services.fleet_queries import fleet_legs
from station.services.serials import SERIAL_RULE, is_serial
from station.catalog import queries  # the fleet's catalog readers beyond history and legs
from station.web import svg
from station.web.extensions import CHART_FIGURES, certificates_of

log = logging.getLogger(__name__)
HERE = Path(__file__).parent
PAGE_SIZE = 50
# the highest page number asked for: 10^6 pages of 50 legs is far beyond any fleet, and a bound
# keeps the offset inside every database's integer (20 digits overflowed SQLite: a 500)
MAX_PAGE = 1_000_000
PAGE_RE = re.compile(r"[1-9][0-9]{0,6}")  # ASCII digits only: int() also takes "+1", "1_0", "١"
# the stages /compare offers: a calibration is compared with calibrations, a verification with verifications
COMPARED_STAGES = {AS_FOUND: "as-found calibrations", AS_LEFT: "as-left verifications"}
CHART_POINTS = 2000  # the most recent calibrations drawn per chart (statistics use all)


class PageError(Exception):
    """A request the view answers with an error page: 400 (bad query) or 404 (nothing there)."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


@dataclass
class WebSettings:
    tolerances: dict[str, dict[str, float]] = field(default_factory=dict)
    decision_tolerances: dict = field(default_factory=dict)  # {type: Tolerance}: the fleet's decisions
    runs_dir: Path | None = None
    interval_days: int = 365
    compare_window_days: float = 90.0  # [catalog] compare_window_days
    where: str = ""  # which catalog, shown in the footer
    check_hint: str = "check the catalog's server and --catalog / [catalog] url"  # the 503 page's advice
    page_size: int = PAGE_SIZE


def _date(name: str, text: str | None) -> str | None:
    if text in (None, ""):
        return None
    try:
        return dt.date.fromisoformat(text).isoformat()
    except ValueError:
        raise PageError(400, f"{name}={text[:40]!r}: not a date; give it as YYYY-MM-DD") from None


def _choice(name: str, text: str | None, known: list[str]) -> str | None:
    if text in (None, ""):
        return None
    if text not in known:
        raise PageError(400, f"{name}={text[:80]!r}: unknown {name}; known: {', '.join(known) or 'none'}")
    return text


def _page(text: str | None) -> int:
    if text in (None, ""):
        return 1
    if not PAGE_RE.fullmatch(text) or int(text) > MAX_PAGE:
        raise PageError(400, f"page={text[:40]!r}: give a page number 1, 2, ... (at most {MAX_PAGE})")
    return int(text)


def _serial(text: str, what: str = "serial") -> str:
    """`text` if it follows the station's serial grammar (station/services/serials.py), else 400:
    a serial with '/' or '..' could name another leg's URL, so none is looked up."""
    if not is_serial(text):
        raise PageError(400, f"{what} {text[:80]!r} is not a serial number: {SERIAL_RULE}")
    return text


# the fleet's sort keys (sort=KEY ascending, sort=-KEY descending; legs without the value last)
SORTS = {"serial": lambda r: r.serial, "type": lambda r: r.leg_type, "calibrations": lambda r: r.calibrations,
         "last": lambda r: r.last_calibration_utc, "station": lambda r: r.station_id, "E": lambda r: r.E_um,
         "B": lambda r: r.B_um, "decision": None, "due": lambda r: r.due}
# rows stored undecided (before revision 0004) decided per request when at most this many, so the
# counts per verdict hold; an older catalog beyond it shows the page's verdicts until rebuilt
UNDECIDED_AT_ONCE = 2000


def _find(text: str | None) -> str | None:
    """The serial search text: printable, at most 64 characters (a serial's length)."""
    if text in (None, ""):
        return None
    if len(text) > 64 or not text.isprintable():
        raise PageError(400, f"serial={text[:40]!r}: give part of a serial (at most 64 printable characters)")
    return text


def _cell(v) -> str:
    """A CSV cell; text a spreadsheet would run as a formula (= + - @ first) is quoted with '."""
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4f}"
    t = str(v)
    return "'" + t if t[:1] in ("=", "+", "-", "@") and not isinstance(v, (int, float)) else t


@functools.lru_cache(maxsize=16384)
def _x(time_utc: str) -> float:
    """A point's x: its time in seconds (cached: the charts of a type draw each session's time
    once per figure)."""
    return parse_utc(time_utc).timestamp()


STAGE_WORDS = {AS_FOUND: "as found", AS_LEFT: "as left"}


def stage_limits(s: "WebSettings", leg_type: str | None) -> dict[str, dict[str, float]]:
    """{stage: {figure: upper limit um}} of `leg_type`: each stage its own limit from
    [tolerances.TYPE] (and .as_found / .as_left), so an as-found point is never read against the
    as-left limit; settings with only the as-left limits (`tolerances`) give the as-left stage."""
    tol = s.decision_tolerances.get(leg_type or "")
    if tol is not None:
        return {st: tol.limits(st) for st in STAGE_WORDS}
    return {AS_LEFT: dict(s.tolerances.get(leg_type or "", {}))}


def limit_lines(figure: str, limits: dict[str, dict[str, float]]) -> list[svg.HLine]:
    """The tolerance line of each stage, one line where both stages share the limit."""
    found, left = limits.get(AS_FOUND, {}).get(figure), limits.get(AS_LEFT, {}).get(figure)
    if found is not None and found == left:
        return [svg.HLine(found, f"tolerance {found:g} µm (as found and as left)", "tol")]
    out = []
    for st, v in ((AS_FOUND, found), (AS_LEFT, left)):
        if v is not None:
            out.append(svg.HLine(v, f"{STAGE_WORDS[st]} tolerance {v:g} µm", "tol", st))
    return out


def _tip(time_utc: str, station: str | None, serial: str | None = None) -> str:
    """A point's session as its tooltip names it: leg, station and start time (what `station
    history` lists, so the session is found there)."""
    return " ".join(x for x in (serial, station or "-", time_utc[:19].replace("T", " ")) if x)


def history_plot(figure: str, by_stage: dict[str, list], limits: dict[str, dict[str, float]]) -> str:
    """`figure` of a leg over its as-found calibrations and as-left verifications, a series per
    stage, each stage's own tolerance line."""
    series, times = [], []
    for st, rows in by_stage.items():
        pts = [svg.Point(_x(c.time_utc), c.figures[figure]["value_um"], c.figures[figure].get("U_um"),
                         _tip(c.time_utc, c.station_id))
               for c in rows if (c.figures.get(figure) or {}).get("value_um") is not None]
        times += [c.time_utc for c in rows]
        series.append(svg.Series(STAGE_WORDS[st].replace(" ", "-"), pts, st))
    times.sort()
    ends = (times[0][:10], times[-1][:10]) if times else ("", "")
    return svg.plot(f"{figure} as found and as left", series, limit_lines(figure, limits), ends, "µm", y_floor=0.0)


def chart_plot(c: queries.Chart) -> str:
    shown = c.values[-CHART_POINTS:]
    ucl, lcl = c.ucl, c.lcl
    pts = [svg.Point(_x(t), v, None, _tip(t, station, serial), c.out_of_control(v))
           for t, serial, station, v in shown]
    lines = []
    if c.mean is not None:
        lines.append(svg.HLine(c.mean, f"mean {c.mean:.2f}", "mean"))
    if c.s is not None:
        lines.append(svg.HLine(ucl, f"+3s {ucl:.2f}", "limit"))
        # E, B, R cannot be negative: a lower limit under 0 is 0 (the axis stops there too)
        lines.append(svg.HLine(max(lcl, 0.0), f"-3s {lcl:.2f}" if lcl > 0 else "-3s below 0: 0", "limit"))
    if c.limit_um is not None:
        lines.append(svg.HLine(c.limit_um, f"{STAGE_WORDS.get(c.stage, '')} tolerance {c.limit_um:g}".strip(), "tol",
                               c.stage))
    ends = (shown[0][0][:10], shown[-1][0][:10]) if shown else ("", "")
    name = STAGE_WORDS.get(c.stage, "all").replace(" ", "-")
    return svg.plot(f"control chart {c.figure} {STAGE_WORDS.get(c.stage, '')}".strip(),
                    [svg.Series(name, pts, c.stage)], lines, ends, "µm", y_floor=0.0)


def compare_plot(item: queries.Compared, figure: str) -> str:
    series = []
    for i, st in enumerate(item.stations):
        x, u = getattr(st, figure)
        if x is not None:
            series.append(svg.Series(st.station_id, [svg.Point(float(i), x, u, st.time_utc[:10])]))
    names = [st.station_id for st in item.stations]
    return svg.plot(f"{figure} of {item.serial} per station", series, [],
                    (names[0], names[-1]) if names else ("", ""), "µm")


def create_app(engine: Engine, settings: WebSettings | None = None) -> FastAPI:
    """The web view over `engine` (open it read-only where the engine allows: `open_readonly`)."""
    s = settings or WebSettings()
    app = FastAPI(title="station fleet", docs_url=None, redoc_url=None, openapi_url=None)
    templates = Jinja2Templates(directory=str(HERE / "templates"))
    # a path segment: '/' encoded too (Jinja's urlencode keeps it, so "A/../HX-0042" would be a
    # link the browser resolves to /leg/HX-0042)
    templates.env.filters["segment"] = lambda v: quote(str(v), safe="")
    templates.env.tests["serial"] = is_serial
    app.mount("/static", StaticFiles(directory=str(HERE / "static")), name="static")

    def page(request: Request, name: str, status_code: int = 200, **context) -> HTMLResponse:
        context.update(where=s.where, user=getattr(request.state, "web_user", None),
                       role=getattr(request.state, "web_role", None))
        return templates.TemplateResponse(request, name, context, status_code=status_code)

    def error_page(request: Request, status: int, message: str) -> HTMLResponse:
        titles = {400: "Bad request", 403: "Forbidden", 404: "Not found", 405: "Method not allowed", 500: "Error",
                  503: "Catalog unreachable"}
        return page(request, "error.html", status, status=status, title=titles.get(status, "Error"), message=message)

    @app.exception_handler(PageError)
    async def _page_error(request: Request, exc: PageError):
        return error_page(request, exc.status, exc.message)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException):
        text = {404: f"nothing at {request.url.path}", 405: "this view is read-only (GET only)"}
        return error_page(request, exc.status_code, text.get(exc.status_code, str(exc.detail)))

    @app.exception_handler(RequestValidationError)
    async def _validation_error(request: Request, exc: RequestValidationError):
        return error_page(request, 400, "; ".join(str(e.get("msg")) for e in exc.errors()))

    @app.exception_handler(sa.exc.DBAPIError)
    async def _database_error(request: Request, exc: sa.exc.DBAPIError):
        # the driver's text names hosts, users and SQL: the log has it, the page says what to check
        if isinstance(exc, (sa.exc.OperationalError, sa.exc.InterfaceError)) or exc.connection_invalidated:
            log.warning("web: %s: catalog unreachable: %s", request.url.path, str(exc.orig).strip().splitlines()[:1])
            return error_page(request, 503, f"the catalog ({s.where.removeprefix('catalog: ')}) does not answer; "
                                            f"{s.check_hint}. This page works again once it answers.")
        return await _unexpected(request, exc)

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception):
        log.exception("web: %s", request.url.path)
        return error_page(request, 500, f"an unexpected error ({type(exc).__name__}); the server log has the details")

    def fleet_rows(request: Request, type, station, since, until, due, decision, find, sort):
        """The legs the fleet's filters keep (not paged), their verdicts, the counts per verdict
        before the decision filter, and the filters as given back: shared by / and /fleet.csv."""
        types, stations = queries.filter_values(engine)
        leg_type = _choice("type", type, types)
        st = _choice("station", station, stations)
        since_d, until_d = _date("since", since), _date("until", until)
        due_d = dt.date.today().isoformat() if due == "today" else _date("due", due)
        verdict = _choice("decision", decision, list(queries.DECISIONS))
        key = _choice("sort", sort, [f"{d}{k}" for k in SORTS for d in ("", "-")])
        find = _find(find)
        rows = fleet_legs(engine, interval_days=s.interval_days, leg_type=leg_type, station=st, since=since_d,
                          until=until_d, due=due_d)  # as `station legs` lists them
        if find:  # the serial search: a part of the serial, any case
            rows = [r for r in rows if find.lower() in r.serial.lower()]
        # verdicts stored at ingest (revision 0004) cost nothing; rows stored undecided are decided
        # here, all of them when few (the counts per verdict stay true), else the page's only
        decided = {r.serial: r.decision for r in rows if r.decision}
        later = [r for r in rows if not r.decision]
        if verdict or len(later) <= UNDECIDED_AT_ONCE:
            decided.update(queries.latest_decisions(engine, {r.serial: r.leg_type for r in later},
                                                    s.decision_tolerances))
            tally = Counter(decided.get(r.serial) for r in rows)  # one pass over the fleet, not one per verdict
            counts = {k: tally[v] for k, v in queries.DECISIONS.items()}
        else:
            counts = None
        if verdict:
            rows = [r for r in rows if decided.get(r.serial) == queries.DECISIONS[verdict]]
        if key:
            name = key.lstrip("-")
            get = SORTS[name] if name != "decision" else (lambda r: decided.get(r.serial))
            present = [r for r in rows if get(r) is not None]
            rows = sorted(present, key=get, reverse=key.startswith("-")) + [r for r in rows if get(r) is None]
        filters = {k: v for k, v in dict(type=leg_type, station=st, since=since_d, until=until_d,
                                         due=due if due == "today" else due_d, decision=verdict, serial=find,
                                         sort=key).items() if v}
        return rows, decided, counts, filters, types, stations, later

    @app.get("/", response_class=HTMLResponse)
    def fleet(request: Request, type: str | None = None, station: str | None = None, since: str | None = None,
              until: str | None = None, due: str | None = None, decision: str | None = None,
              serial: str | None = None, sort: str | None = None):
        n = _page(request.query_params.get("page"))
        rows, decided, counts, filters, types, stations, later = fleet_rows(request, type, station, since, until, due,
                                                                            decision, serial, sort)
        pages = max(1, -(-len(rows) // s.page_size))
        if n > pages:
            raise PageError(404, f"page {n}: there are {pages} page(s) of legs with these filters")
        shown = rows[(n - 1) * s.page_size: n * s.page_size]
        if counts is None:  # many rows stored undecided: the page's legs decided now
            decided.update(queries.latest_decisions(engine, {r.serial: r.leg_type for r in shown if not r.decision},
                                                    s.decision_tolerances))
        with_tolerance = sum(v for k, v in (counts or {}).items() if k != "no-tolerance")
        unsorted = {k: v for k, v in filters.items() if k != "sort"}
        return page(request, "fleet.html", rows=shown, total=len(rows), page_no=n, pages=pages, types=types,
                    stations=stations, filters=filters, qs=urlencode(filters), sort_qs=urlencode(unsorted),
                    today=dt.date.today().isoformat(), decisions=queries.DECISIONS, decided=decided, counts=counts,
                    with_tolerance=with_tolerance, not_at_ingest=len(later), sorts=list(SORTS),
                    sort=filters.get("sort", ""))

    @app.get("/fleet.csv")
    def fleet_csv(request: Request, type: str | None = None, station: str | None = None, since: str | None = None,
                  until: str | None = None, due: str | None = None, decision: str | None = None,
                  serial: str | None = None, sort: str | None = None):
        """Every leg the filters keep (not paged) as CSV, the columns of the fleet page."""
        rows, decided, counts, *_ = fleet_rows(request, type, station, since, until, due, decision, serial, sort)
        if counts is None:
            decided.update(queries.latest_decisions(engine, {r.serial: r.leg_type for r in rows if not r.decision},
                                                    s.decision_tolerances))
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["serial", "leg_type", "part_number", "calibrations", "verifications", "last_calibration_utc",
                    "station", "E_um", "B_um", "decision", "due"])
        for r in rows:
            w.writerow([_cell(x) for x in (r.serial, r.leg_type, r.part_number, r.calibrations, r.verifications,
                                           r.last_calibration_utc, r.station_id, r.E_um, r.B_um,
                                           decided.get(r.serial), r.due)])
        return Response(buf.getvalue(), media_type="text/csv; charset=utf-8",
                        headers={"Content-Disposition": 'attachment; filename="fleet.csv"'})

    @app.get("/leg/{serial}", response_class=HTMLResponse)
    def leg(request: Request, serial: str):
        _serial(serial)
        h = history(engine, serial, s.interval_days)
        if not h.rows and not h.leg_info:
            raise PageError(404, f"no leg with serial {serial!r} in the catalog")
        leg_type = h.leg_info.get("leg_type")
        limits = stage_limits(s, leg_type)
        by_stage = {AS_FOUND: h.calibrations, AS_LEFT: h.verifications}
        plots = {f: history_plot(f, by_stage, limits) for f in CHART_FIGURES}
        pushes = [r for r in h.rows if r.kind in ("push", "rollback")]
        tables = [r for r in h.rows if r.kind == "table"]
        files = queries.table_files(engine, sorted({r.table_sha256 for r in pushes if r.table_sha256}))
        return page(request, "leg.html", serial=serial, h=h, leg_type=leg_type, limits=limits, plots=plots,
                    stage_words=STAGE_WORDS,
                    pushes=pushes, tables=tables, files=files, certificates=certificates_of(s.runs_dir, serial),
                    figures=CHART_FIGURES)

    @app.get("/leg/{serial}/certificate/{name}")
    def certificate(request: Request, serial: str, name: str):
        _serial(serial)
        role = getattr(request.state, "web_role", None)
        if role is not None and role != "auditor":
            raise PageError(403, f"certificates are downloaded by an auditor; {request.state.web_user} is a {role} "
                                 "([web.users.NAME] role in the station config)")
        for c in certificates_of(s.runs_dir, serial):
            if c.pdf_name == name:
                return FileResponse(c.pdf_path, media_type="application/pdf", filename=name)
        raise PageError(404, f"no certificate {name!r} for leg {serial!r}")

    @app.get("/charts", response_class=HTMLResponse)
    def charts(request: Request, type: str | None = None):
        types, _ = queries.filter_values(engine)
        leg_type = _choice("type", type, types) or (types[0] if types else None)
        limits = stage_limits(s, leg_type)
        # one chart per stage and figure: as-found and as-left values are different populations
        # (before and after compensation), each against its own limit, with its own Cpk
        cs = queries.charts_of_type(engine, leg_type, tuple(STAGE_WORDS), CHART_FIGURES, limits, CHART_POINTS) \
            if leg_type else []
        counts = {st: max([c.count for c in cs if c.stage == st], default=0) for st in STAGE_WORDS}
        return page(request, "charts.html", types=types, leg_type=leg_type, charts=cs, stage_words=STAGE_WORDS,
                    plots={(c.stage, c.figure): chart_plot(c) for c in cs}, calibrations=counts,
                    chart_points=CHART_POINTS)

    @app.get("/compare", response_class=HTMLResponse)
    def compare(request: Request, type: str | None = None, serial: str | None = None, stage: str | None = None):
        types, _ = queries.filter_values(engine)
        leg_type = _choice("type", type, types)
        st = _choice("stage", stage, list(COMPARED_STAGES)) or AS_FOUND
        if serial:
            _serial(serial, "serial=")
        n = _page(request.query_params.get("page"))
        items, total = queries.compared_serials(engine, leg_type, serial or None, s.page_size, (n - 1) * s.page_size,
                                                stage=st, window_days=s.compare_window_days)
        if serial and not items:
            raise PageError(404, f"leg {serial!r} has no completed {COMPARED_STAGES[st]} at more than one station")
        pages = max(1, -(-total // s.page_size))
        if n > pages:
            raise PageError(404, f"page {n}: there are {pages} page(s) of compared legs")
        plots = {f: compare_plot(items[0], f) for f in ("E", "B")} if serial else {}
        # one leg: every pair's table target by target (deviations, U, E_n), as `station compare` prints
        targets = queries.per_target(engine, items[0]) if serial else []
        return page(request, "compare.html", items=items, total=total, types=types, leg_type=leg_type,
                    serial=serial, plots=plots, page_no=n, pages=pages, stage=st, stages=COMPARED_STAGES,
                    window_days=s.compare_window_days, targets=targets)

    from station.web import certificates  # noqa: PLC0415  (its routes: station/web/certificates.py)

    certificates.add_routes(app, engine, page, PageError)
    return app
