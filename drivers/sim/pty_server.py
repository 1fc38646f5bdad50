"""The lifecycle the simulated serial instruments share: a real pseudo-terminal served by one thread.

`PtyServer.start()` opens the pty (raw: no echo, no CR/LF translation, no line editing), keeps the
slave open for the server's lifetime (otherwise reading the master fails with EIO whenever no
client has the port open), and runs `_serve()` in a daemon thread; `stop()` wakes it through a
pipe, joins it and closes every descriptor. Subclasses write `_serve()`: it selects on
`self._master` and `self._wake_r` and returns once the wake-up pipe is readable.
"""

from __future__ import annotations

import os
import threading
import tty


class PtyServer:
    """Base of a simulated instrument on a pty (drivers/sim/interferometer_server.py,
    drivers/sim/linef1_server.py). `name` labels its thread and its errors."""

    name = "simulated instrument"

    def _init_pty(self) -> None:
        self._master = self._slave = self._wake_r = self._wake_w = -1
        self._thread: threading.Thread | None = None
        self.port: str | None = None

    def _serve(self) -> None:  # pragma: no cover - every subclass has its own
        raise NotImplementedError

    def start(self) -> str:
        """Open the pty, start serving; returns the slave path to give to the client."""
        if self._thread is not None:
            raise RuntimeError(f"{self.name} already started")
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # raw before anyone writes
        self._wake_r, self._wake_w = os.pipe()
        self.port = os.ttyname(self._slave)
        self._thread = threading.Thread(target=self._serve, name=f"{self.name} {self.port}", daemon=True)
        self._thread.start()
        return self.port

    def stop(self) -> None:
        """Stop serving and close every descriptor. Safe to call twice."""
        if self._thread is None:
            return
        os.write(self._wake_w, b"x")
        self._thread.join(timeout=5.0)
        if self._thread.is_alive():  # pragma: no cover - would be a bug in _serve
            raise RuntimeError(f"{self.name} thread did not stop")
        self._thread = None
        for fd in (self._master, self._slave, self._wake_r, self._wake_w):
            os.close(fd)
        self._master = self._slave = self._wake_r = self._wake_w = -1

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
