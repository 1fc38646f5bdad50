"""A real server and a real browser for the web view's tests and bench: uvicorn on 127.0.0.1 (a
free port, a thread) and Debian's headless Chromium through chromedriver (selenium)."""

from __future__ import annotations

import shutil
import socket
import threading
import time
from pathlib import Path

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# a name Chromium resolves to 127.0.0.1 (--host-resolver-rules), as a DNS-rebinding attacker's
# name would: pages reached by it must be refused by the Host check
REBIND_NAME = "rebind.test"


class Server:
    """uvicorn serving `app` on 127.0.0.1 (a free port) in a thread (stopped by `stop`), behind the
    same guard as `station web` (station/web/access.Guard: Host check, security headers, and the
    login when `login`), on a socket bound as `station web` binds it (station/web/listen.bind)."""

    def __init__(self, app, access=None, login: bool = False) -> None:
        import uvicorn

        from station.web.access import Guard, WebAccess
        from station.web.listen import bind

        self.sock = bind("127.0.0.1", 0)
        self.port = self.sock.getsockname()[1]
        guarded = Guard(app, host="127.0.0.1", port=self.port, access=access or WebAccess(), login=login)
        self.server = uvicorn.Server(uvicorn.Config(guarded, log_level="warning"))
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 15
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("uvicorn did not start")
            time.sleep(0.02)
        self.url = f"http://127.0.0.1:{self.port}"

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(10)
        self.sock.close()


def chromium(profile: Path, downloads: Path):
    """Headless Chromium (a fresh profile, no network of its own, downloads into `downloads`,
    console entries kept for get_log('browser'))."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for arg in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync",
                "--disable-dev-shm-usage", "--window-size=1300,1700", f"--user-data-dir={profile}",
                f"--host-resolver-rules=MAP {REBIND_NAME} 127.0.0.1"):
        opts.add_argument(arg)
    opts.add_experimental_option("prefs", {"download.default_directory": str(downloads),
                                           "download.prompt_for_download": False,
                                           "plugins.always_open_pdf_externally": True})
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(DRIVER), options=opts)
