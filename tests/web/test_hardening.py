"""The web view hardened (issue 31, part 6), in a real headless Chromium against uvicorn on
127.0.0.1 behind `station web`'s guard (station/web/access.py), and `station web` itself:

- serials: every leg link opens the page of the serial it shows; serials an older station let
  in with '/' ("A/../HX-0042", "HX/0043") are listed without a link, and no URL made of them
  shows another leg; the serial grammar refuses them wherever serials enter;
- page numbers out of range (20 digits, 0, "+1", "1e3", above 10^6): 400, never a 500;
- the catalog's PostgreSQL server stopped: a 503 page naming what to check (no driver text),
  and the pages back once it runs again;
- the Host header: a page reached under another name (a DNS-rebinding name Chromium resolves to
  127.0.0.1) is refused; CSP with frame-ancestors, nosniff on every response, and a real framing
  refused by Chromium;
- the login (forced on a loopback bind: tests never listen beyond it), roles;
- `station web`'s refusals: one line on stderr, exit 2, nothing on stdout (no URL printed).
"""

from __future__ import annotations

import base64
import hashlib
import html
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from station.catalog import db
from station.catalog.readers import Rec
from station.catalog.store import Catalog, write_recs
from station.web.access import WebAccess, WebUser, hash_password
from tests.web import fleet
from tests.web.browser import REBIND_NAME, Server
from tests.web.conftest import need_browser, web_app

LEGACY = ("A/../HX-0042", "HX/0043")  # serials an older station accepted ('/' was in the rule)
PASSWORDS = {"vera": "viewer-password-1", "audrey": "auditor-password-1"}


def _session(serial: str, e: float) -> Rec:
    key = hashlib.sha256(f"hardening|{serial}".encode()).hexdigest()
    rec = Rec(kind="session", key=key, time_utc="2025-05-01T09:00:00Z", station_id="ST-A", operator="test",
              outcome="completed", path=f"/runs/{key[:8]}.h5", sha256=key)
    rec.legs[1] = {"leg_serial": serial, "E_um": e, "E_U_um": 0.5, "B_um": 1.0, "B_U_um": 0.5, "R_um": 2.0,
                   "R_U_um": 0.5}
    rec.leg_info[serial] = {"leg_type": "L300"}
    return rec


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The known fleet, HX-0042, and the two legacy serials (written through the catalog's API, as
    an older station's sessions were indexed), with a certificate for HX-0001 and one for HX/0043."""
    d = tmp_path_factory.mktemp("hardened")
    cat = Catalog(local=d / "catalog.sqlite", station_id="ST-X")
    cat.ingest(fleet.records() + [_session("HX-0042", 5.0)] + [_session(s, 9.0) for s in LEGACY])
    cat.close()
    fleet.write_certificate(d)
    fleet.write_certificate(d, serial="HX/0043", number="C-2025-0043")
    (d / "station.toml").write_text(fleet.TOLERANCES_TOML)
    return d


@pytest.fixture(scope="module")
def site(runs):
    need_browser()
    app, engine = web_app(db.sqlite_url(runs / "catalog.sqlite"), runs, page_size=50)
    server = Server(app)
    yield server
    server.stop()
    engine.dispose()


def get(url: str, headers: dict | None = None) -> tuple[int, dict, bytes]:
    """A plain HTTP GET over loopback: (status, headers lower-cased, body)."""
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, {k.lower(): v for k, v in r.headers.items()}, r.read()
    except urllib.error.HTTPError as e:
        return e.code, {k.lower(): v for k, v in e.headers.items()}, e.read()


def heading(browser) -> str:
    return browser.find_element("tag name", "h1").text


def message(browser) -> str:
    return browser.find_element("id", "message").text


# ---------------------------------------------------------------------------- serials

def test_every_leg_link_opens_the_leg_it_names(browser, site):
    from selenium.webdriver.common.by import By

    browser.get(site.url + "/")
    links = [(a.text, a.get_attribute("href")) for a in browser.find_elements(By.CSS_SELECTOR, "#legs tr.leg td a")]
    unlinked = [e.text for e in browser.find_elements(By.CSS_SELECTOR, "#legs tr.leg td span.badserial")]
    assert sorted(unlinked) == sorted(LEGACY)  # listed, never a link a browser would resolve elsewhere
    assert {t for t, _ in links} == set(fleet.TYPES) | {"HX-0042"}
    for text, href in links:
        browser.get(href)
        assert heading(browser) == f"Leg {text}", href


@pytest.mark.parametrize("path, status", [
    ("/leg/A%2F..%2FHX-0042", "404"),            # the legacy serial, encoded: not HX-0042's page
    ("/leg/..%2FHX-0042", "404"),
    ("/leg/HX%2F0043", "404"),
    ("/leg/HX%2F0043/certificate/C-2025-0043_r1.pdf", "404"),
    ("/leg/.HX-0042", "400"),                     # outside the grammar: refused, not looked up
    ("/leg/HX-0042%00", "400"),
    ("/compare?serial=A%2F..%2FHX-0042", "400"),
])
def test_no_url_shows_another_leg(browser, site, path, status):
    browser.get(site.url + path)
    assert heading(browser).startswith(status), (path, heading(browser))
    assert "HX-0042" not in heading(browser)
    assert not browser.find_elements("id", "plot-E")  # no leg's history drawn
    if status == "400" and path.startswith("/leg/"):
        assert "is not a serial number: 1..64 letters, digits" in message(browser)


def test_dot_segments_sent_raw_are_refused(site):
    """A client that does not normalise dot segments (Chromium does) gets 400, not a leg."""
    import http.client

    for raw in ("/leg/..", "/leg/.", "/leg/..%2FHX-0042"):
        conn = http.client.HTTPConnection("127.0.0.1", site.port, timeout=10)
        conn.request("GET", raw)
        r = conn.getresponse()
        body = r.read().decode()
        conn.close()
        assert r.status in (400, 404) and "Leg HX-0042" not in body, (raw, r.status)
        if raw in ("/leg/..", "/leg/."):
            assert r.status == 400 and "is not a serial number" in body, raw


def test_the_serial_grammar_refuses_slashes_wherever_serials_enter(tmp_path, capsys):
    from procedures.vocabulary import InputError
    from station.cli import main
    from station.services.config import load_config
    from station.services.serials import parse_serial_args, read_serials_file

    with pytest.raises(InputError, match=r"--serial 3=HX/0043: serial 'HX/0043' is not a serial number.*'/' is "
                                         r"not allowed"):
        parse_serial_args(["3=HX/0043"])  # the CLI's --serial and the TUI's Serials field
    f = tmp_path / "serials.csv"
    f.write_text("leg,serial\n1,HX-0001\n2,A/../HX-0042\n")
    with pytest.raises(InputError, match=r"serials.csv: row 3, field serial: serial 'A/../HX-0042'"):
        read_serials_file(f)
    c = tmp_path / "c.toml"
    c.write_text('[legs.3]\nserial = "HX/0043"\n')
    with pytest.raises(InputError, match=r"c.toml: \[legs.3\] serial: serial 'HX/0043'"):
        load_config(c)
    for argv in (["history", "HX/0043"], ["certificate", "--serial", "A/../HX-0042"]):
        assert main(argv) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1 and "is not a serial number" in err, (argv, err)


# ---------------------------------------------------------------------------- page numbers

@pytest.mark.parametrize("query", ["/compare?page=99999999999999999999", "/?page=99999999999999999999",
                                   "/?page=1000001", "/?page=0", "/compare?page=-1", "/?page=%2B1", "/?page=1e3",
                                   "/compare?page=1_0", "/?page=%D9%A1"])
def test_page_numbers_out_of_range_are_400(browser, site, query):
    browser.get(site.url + query)
    assert heading(browser) == "400 Bad request", query
    assert "give a page number 1, 2, ... (at most 1000000)" in message(browser)


def test_page_within_range_past_the_last_is_404(browser, site):
    browser.get(site.url + "/?page=1000000")
    assert heading(browser) == "404 Not found" and "there are 1 page(s)" in message(browser)


# ---------------------------------------------------------------------------- Host, headers

def test_host_header_checked_against_the_listening_address(browser, site):
    from selenium.webdriver.common.by import By

    # Chromium resolves the name to 127.0.0.1, as a rebinding attacker's DNS would: same socket,
    # same server, but the Host is the attacker's name
    browser.get(f"http://{REBIND_NAME}:{site.port}/leg/HX-0001")
    assert heading(browser) == "400 Bad request"
    assert message(browser).startswith(f"Host '{REBIND_NAME}:{site.port}' is not this server: it listens on "
                                       f"127.0.0.1:{site.port}")
    assert "HX-0001" not in browser.find_element(By.TAG_NAME, "body").text.replace(message(browser), "")
    browser.get(f"http://localhost:{site.port}/")  # this machine's own name is the listening address
    assert browser.find_elements(By.CSS_SELECTOR, "#legs tr.leg")
    assert get(site.url + "/", {"Host": f"127.0.0.1:{site.port + 1}"})[0] == 400  # another port


def test_security_headers_on_every_response(browser, site):
    cases = {"/": 200, "/leg/HX-0001": 200, "/static/style.css": 200, "/leg/HX-9999": 404, "/?page=0": 400,
             "/leg/HX-0001/certificate/C-2025-0001_r1.pdf": 200}
    for path, status in cases.items():
        code, headers, _ = get(site.url + path)
        assert code == status, path
        csp = headers.get("content-security-policy", "")
        assert "default-src 'none'" in csp and "frame-ancestors 'none'" in csp, path
        assert headers.get("x-content-type-options") == "nosniff", path
        assert headers.get("x-frame-options") == "DENY", path
    code, headers, _ = get(site.url + "/", {"Host": "evil.example"})
    assert code == 400 and "frame-ancestors 'none'" in headers["content-security-policy"]
    # the pages keep working under the policy: the stylesheet applies, nothing is blocked
    browser.get_log("browser")
    browser.get(site.url + "/leg/HX-0001")
    assert not [e for e in browser.get_log("browser") if e.get("level") == "SEVERE"]
    assert browser.find_element("css selector", "nav").value_of_css_property("display") != ""
    # and Chromium refuses to show the view inside a frame, where a plain page (the control,
    # without the headers) is shown
    assert framed_text(browser, _plain_page_url().replace("127.0.0.1", "localhost")) == "framed fine"  # cross-origin
    assert framed_text(browser, site.url + "/") == ""


def framed_text(browser, url: str) -> str:
    """The text of an <h1> of `url` loaded in an iframe of another origin's page on 127.0.0.1
    ("" when none shows)."""
    from urllib.parse import quote

    browser.get(_plain_page_url() + "frame?src=" + quote(url, safe=""))
    time.sleep(1.0)
    browser.switch_to.frame(browser.find_element("id", "f"))
    try:
        found = browser.find_elements("css selector", "h1")
        return found[0].text if found else ""
    finally:
        browser.switch_to.default_content()


_PLAIN: list = []


def _plain_page_url() -> str:
    """A page without any header, served by the standard library on 127.0.0.1 (kept for the run)."""
    import threading
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    if not _PLAIN:
        class Plain(BaseHTTPRequestHandler):
            def do_GET(self):
                from urllib.parse import parse_qs, urlsplit

                u = urlsplit(self.path)
                if u.path == "/frame":  # a page that frames ?src=
                    src = html.escape(parse_qs(u.query)["src"][0])
                    body = f'<!doctype html><iframe id="f" src="{src}"></iframe>'.encode()
                else:
                    body = b"<!doctype html><h1>framed fine</h1>"
                self.send_response(200)
                self.send_header("Content-Type", "text/html")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args):
                pass

        srv = ThreadingHTTPServer(("127.0.0.1", 0), Plain)
        threading.Thread(target=srv.serve_forever, daemon=True).start()
        _PLAIN.append(srv)
    return f"http://127.0.0.1:{_PLAIN[0].server_address[1]}/"


# ---------------------------------------------------------------------------- database down

@pytest.fixture(scope="module")
def pg_site(runs):
    need_browser()
    from tests.pg import remove, start_cluster

    cluster = start_cluster()
    try:
        url = cluster.new_database()
        engine = db.open_engine(url)
        with engine.begin() as conn:
            write_recs(conn, fleet.records(), "ST-X", queue=False)
        engine.dispose()
        app, engine = web_app(url, runs, page_size=50)
        server = Server(app)
        yield server, cluster
        server.stop()
        engine.dispose()
    finally:
        remove(cluster)


def test_catalog_down_is_a_503_page_naming_what_to_check(browser, pg_site):
    from selenium.webdriver.common.by import By

    server, cluster = pg_site
    browser.get(server.url + "/")
    assert len(browser.find_elements(By.CSS_SELECTOR, "#legs tr.leg")) == fleet.EXPECT["legs"]
    cluster.stop()
    try:
        for path in ("/", "/leg/HX-0001", "/charts", "/compare"):
            browser.get(server.url + path)
            assert heading(browser) == "503 Catalog unreachable", path
            text = message(browser)
            assert "does not answer; check that the PostgreSQL server at the socket in" in text, text
            assert "is running" in text and "pg_isready" in text
            page = browser.page_source
            for leak in ("OperationalError", "psycopg", "sqlalchemy", "connection failed", "Traceback"):
                assert leak not in page, (path, leak)
    finally:
        cluster.start()
    browser.get(server.url + "/")  # back on its own once the server answers
    assert len(browser.find_elements(By.CSS_SELECTOR, "#legs tr.leg")) == fleet.EXPECT["legs"]


# ---------------------------------------------------------------------------- login

def _basic(user: str, password: str) -> dict:
    return {"Authorization": "Basic " + base64.b64encode(f"{user}:{password}".encode()).decode()}


@pytest.fixture(scope="module")
def login_site(runs):
    """The view with the login forced on a loopback bind ([web] login = "always"): the path a
    bind beyond loopback takes, without listening beyond it."""
    need_browser()
    access = WebAccess(login="always", users={
        "vera": WebUser("vera", hash_password(PASSWORDS["vera"]), "viewer"),
        "audrey": WebUser("audrey", hash_password(PASSWORDS["audrey"]), "auditor")})
    app, engine = web_app(db.sqlite_url(runs / "catalog.sqlite"), runs, page_size=50)
    server = Server(app, access=access, login=True)
    yield server
    server.stop()
    engine.dispose()


def test_login_required_and_roles(browser, login_site):
    base = login_site.url
    for path in ("/", "/static/style.css", "/leg/HX-0001"):
        code, headers, body = get(base + path)
        assert code == 401 and headers["www-authenticate"].startswith('Basic realm="station fleet"'), path
        assert b"HX-0001" not in body and "frame-ancestors 'none'" in headers["content-security-policy"]
    assert get(base + "/", _basic("vera", "wrong-password"))[0] == 401
    assert get(base + "/", _basic("nobody", PASSWORDS["vera"]))[0] == 401
    code, _, body = get(base + "/", _basic("vera", PASSWORDS["vera"]))
    assert code == 200 and b'logged in as <span id="user">vera</span> (viewer)' in body
    cert = "/leg/HX-0001/certificate/C-2025-0001_r1.pdf"
    code, _, body = get(base + cert, _basic("vera", PASSWORDS["vera"]))
    assert code == 403 and b"certificates are downloaded by an auditor" in body
    code, _, body = get(base + cert, _basic("audrey", PASSWORDS["audrey"]))
    assert code == 200 and body.startswith(b"%PDF")
    # in Chromium, with the credentials the browser would send after its login prompt
    browser.execute_cdp_cmd("Network.enable", {})
    browser.execute_cdp_cmd("Network.setExtraHTTPHeaders", {"headers": _basic("audrey", PASSWORDS["audrey"])})
    try:
        browser.get(base + "/leg/HX-0001")
        assert heading(browser) == "Leg HX-0001"
        assert browser.find_element("id", "user").text == "audrey"
        assert browser.find_elements("css selector", "#certificates a")
    finally:
        browser.execute_cdp_cmd("Network.setExtraHTTPHeaders", {"headers": {}})


# ---------------------------------------------------------------------------- `station web`

def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_station_web_refusals_are_one_line_before_any_url(tmp_path, capsys, runs, monkeypatch):
    from station.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.toml").write_text('[station]\nid = "a"\n')
    dead = f"postgresql://u:secret@127.0.0.1:{_closed_port()}/x"
    (tmp_path / "pg.toml").write_text(f'[catalog]\nurl = "{dead}"\nconnect_timeout_s = 1\n')
    (tmp_path / "always.toml").write_text('[web]\nlogin = "always"\n')
    (tmp_path / "plain.toml").write_text('[web]\n[web.users.bob]\npassword_hash = "hunter2"\n')
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    cat = str(runs / "catalog.sqlite")
    cases = [
        (["--port", "99999"], "outside 1 .. 65535; give a TCP port"),
        (["--port", "-1"], "outside 1 .. 65535; give a TCP port"),
        (["--catalog", cat, "--port", str(busy.getsockname()[1])], "the port is in use (another `station web`?)"),
        (["--catalog", dead, "--port", str(_closed_port())], "postgresql://u:***@127.0.0.1"),
        (["--config", "pg.toml", "--port", str(_closed_port())], "not reachable within 1 s; check that the "
                                                                  "PostgreSQL server at 127.0.0.1:"),
        (["--catalog", "x.toml", "--port", str(_closed_port())], "x.toml"),
        # refused before binding; were the check lost, the catalog (a server that does not answer)
        # would still stop it before anything listens
        (["--host", "0.0.0.0", "--catalog", dead], "--host 0.0.0.0: listening beyond this machine needs a login"),
        (["--config", "always.toml", "--catalog", dead], 'login = "always" but no [web.users.NAME]'),
        (["--config", "plain.toml", "--catalog", dead], "password_hash: not an argon2 hash"),
    ]
    try:
        for argv, said in cases:
            rc = main(["web", *argv])
            out, err = capsys.readouterr()
            assert rc == 2 and out == "", (argv, out, err)
            assert err.count("\n") == 1 and said in err and "Traceback" not in err, (argv, err)
            if "x.toml" in argv:  # refused as no SQLite catalog (here or by station/values.py's CATALOG)
                assert "SQLite" in err
            assert "secret" not in err and "OperationalError" not in err
    finally:
        busy.close()


def test_station_web_serves_with_login_and_refuses_its_busy_port(tmp_path, runs, capsys, monkeypatch):
    """The command as an operator runs it: login forced in the config, the URL printed once it
    listens; a second one on the same port is one line, exit 2, no URL."""
    cfg = tmp_path / "web.toml"
    cfg.write_text(f'[web]\nlogin = "always"\n[web.users.vera]\npassword_hash = "{hash_password("pw-for-vera-1")}"\n'
                   'role = "viewer"\n')
    port = _closed_port()
    argv = [str(Path(sys.executable).with_name("station")), "web", "--config", str(cfg), "--catalog", str(runs / "catalog.sqlite"), "--port", str(port)]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    try:
        line = proc.stdout.readline()
        assert line.startswith(f"station web: http://127.0.0.1:{port}/ (catalog: ") and "login required" in line, line
        base = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 15
        while True:  # the URL is printed just before uvicorn starts serving the bound socket
            try:
                code = get(base + "/")[0]
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)
        assert code == 401
        assert get(base + "/", _basic("vera", "pw-for-vera-1"))[0] == 200
        from station.cli import main  # the second one in process: the same code, no second start-up

        monkeypatch.chdir(tmp_path)
        assert main(argv[1:]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err == f"station web: error: 127.0.0.1:{port}: the port is in use (another " \
                                    "`station web`?); stop it or give another --port\n"
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()


@pytest.mark.parametrize("host, ok", [
    ("127.0.0.1:8800", True), ("localhost:8800", True), ("[::1]:8800", True), ("LOCALHOST.:8800", True),
    ("127.0.0.1", True),                       # no port: the default of the scheme, still this address
    ("127.0.0.1:8801", False), ("rebind.test:8800", False), ("evil.example", False), ("", False),
    ("127.0.0.1:abc", False), ("127.0.0.1:0", False), ("[::1", False), ("[::1]x", False),
    ("fleet.lab.example", True), ("fleet.lab.example:443", True),  # [web] allowed_hosts: a proxy's name
    ("10.0.0.7:8800", False),                  # an address, but not the one listened on
])
def test_host_rule_on_loopback(host, ok):
    from station.web.access import allowed_host_names, host_allowed

    access = WebAccess(allowed_hosts=["fleet.lab.example"])
    names = allowed_host_names("127.0.0.1", access)
    assert host_allowed(host, names, 8800, wildcard=False, proxy_names=set(access.allowed_hosts)) is ok


def test_host_rule_on_every_interface():
    """Listening on 0.0.0.0 (checked without listening): an address is allowed (a rebinding page
    is reached by a name), this machine's own name too, another name not."""
    from station.web.access import allowed_host_names, host_allowed

    names = allowed_host_names("0.0.0.0", WebAccess())
    assert host_allowed("192.0.2.10:8800", names, 8800, wildcard=True)
    assert host_allowed(f"{socket.gethostname()}:8800", names, 8800, wildcard=True)
    assert not host_allowed("rebind.test:8800", names, 8800, wildcard=True)
    assert not host_allowed("192.0.2.10:9999", names, 8800, wildcard=True)


def test_hash_password_prints_an_argon2id_hash_the_login_accepts(monkeypatch, capsys, tmp_path):
    import io

    from argon2 import PasswordHasher

    from station.cli import main
    from station.web.access import parse_web_section

    monkeypatch.setattr(sys, "stdin", io.StringIO("a-long-password\n"))
    assert main(["web", "--hash-password"]) == 0
    out, err = capsys.readouterr()
    h = out.strip()
    assert out.count("\n") == 1 and h.startswith("$argon2id$") and PasswordHasher().verify(h, "a-long-password")
    access = parse_web_section(tmp_path / "c.toml", {"users": {"qa": {"password_hash": h, "role": "auditor"}}})
    assert access.users["qa"].role == "auditor"
    monkeypatch.setattr(sys, "stdin", io.StringIO("short\n"))
    assert main(["web", "--hash-password"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == "station web: error: password: give at least 12 characters\n"
