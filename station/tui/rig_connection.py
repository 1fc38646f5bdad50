"""The rig connection: (re)connecting in a worker, the answers it posts, the rig's state the screens read."""

from __future__ import annotations

import threading

from textual import work

from station.services.rig_session import MoveRequest, close_quietly
from station.tui.error_text import describe
from station.tui.messages import RigConnected, RigConnectFailed


class RigConnection:
    """The app's part that holds the rig session (`self.session`: station.services.rig_session.
    RigSession, assigned in StationApp.__init__) and connects it. The connection is assigned on the
    app's thread only: a worker opens the rig and posts RigConnected / RigConnectFailed, the
    handlers here take it in. Uses of the app: `notify`, `hide_volatile`, `sweep_refusal`
    (station.tui.job_dispatch), `_rig_changed` (station.tui.redraws)."""

    # -- the rig session's state, as the screens read it ----------------------------------------
    @property
    def rig(self):
        """station.services.wiring.Rig once connected, else None."""
        return self.session.rig

    @rig.setter
    def rig(self, rig) -> None:
        self.session.rig = rig

    @property
    def rig_state(self) -> str:
        return self.session.state  # "connecting" / "connected" / "not connected"

    @property
    def rig_error(self) -> str:
        return self.session.error

    @property
    def rig_lock(self) -> threading.Lock:
        return self.session.lock

    @property
    def rig_motion(self) -> dict[int, MoveRequest]:
        return self.session.motion  # leg -> the move/jog under way (Rig page)

    @property
    def rig_motion_text(self) -> str:
        return self.session.motion_text  # how the last move/jog ended, for the Rig page

    # -- connecting ------------------------------------------------------------------------------
    def action_connect(self) -> None:
        refusal = self.sweep_refusal()
        if refusal:
            self.notify(refusal, title="Reconnect", severity="warning")
            return
        self.connect_rig()

    def connect_rig(self) -> None:
        """(Re)connect. The current rig is detached here, on the app's thread, so `app.rig` never
        names a rig that is being closed; the worker closes it, then opens the new one."""
        old, attempt = self.session.detach()
        self._rig_changed()
        self._connect_worker(old, attempt, self.session.lock)

    @work(thread=True, group="connect", exit_on_error=False)
    def _connect_worker(self, old, attempt: int, lock: threading.Lock) -> None:
        try:  # a poll or an action still using the old rig finishes first (the session takes the lock)
            rig = self.session.open_rig_for(old, lock)
        except Exception as exc:
            self.post_message(RigConnectFailed(describe(exc, "cannot connect to the rig"), attempt))
            return
        self.post_message(RigConnected(rig, attempt))

    def on_rig_connected(self, message: RigConnected) -> None:
        if not self.session.accept(message.rig, message.attempt):  # a newer connect request is under way
            self._close_worker(message.rig)
            return
        self.notify(f"Connected: {self._rig_kind_text()}.", timeout=4)
        self._rig_changed()

    def on_rig_connect_failed(self, message: RigConnectFailed) -> None:
        if not self.session.fail(message.error, message.attempt):
            return
        self.notify(message.error + " Press c on the Rig screen (F1) to retry.", title="Rig",
                    severity="error", timeout=15)
        self._rig_changed()

    @work(thread=True, group="connect", exit_on_error=False)
    def _close_worker(self, rig) -> None:
        close_quietly(rig, "closing a superseded rig failed")

    def _rig_kind_text(self) -> str:
        return self.session.kind_text(self.hide_volatile)
