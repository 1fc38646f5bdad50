"""The rig actions (enable, disable, home, reset, stop, move) in a worker, and how their ends are shown."""

from __future__ import annotations

import threading

from textual import work
from textual.notifications import Notification, Notify

from station.services.rig_session import ActionRefused, MoveRequest, MoveStopped, checked_move, rig_action
from station.tui.error_text import describe
from station.tui.messages import RigActionDone, RigMoveDone

# The keys of the rig actions a refusal names as the way out (station.services.rig_session.REMEDIES).
RIG_KEYS = {"reset": "r", "enable": "e", "stop": "x"}


class RigActions:
    """The app's part that runs the Rig page's actions. A worker gets the rig and its lock as
    arguments and posts RigActionDone / RigMoveDone; the handlers here show them. Owns
    `_stop_notices` (assigned in StationApp.__init__). Uses of the app: `rig`, `rig_lock`,
    `rig_motion_text`, `session` (station.tui.rig_connection), `sweep_refusal`
    (station.tui.job_dispatch), `_rig_changed` (station.tui.redraws), `notify`."""

    def rig_action(self, action: str, legs: tuple[int, ...], move: MoveRequest | None = None) -> bool:
        """Run a rig action on `legs` in a worker; True if it was started. Refused while a sweep
        holds the rig (except "stop", which always goes through and quick-stops a move too).
        "move" takes one leg and `move` (where to, how fast); it is refused while another move
        runs, and the worker refuses it on a leg in fault or not enabled, or beyond the drive's
        soft limits, before anything moves (station.services.rig_session.move_axis)."""
        if self.rig is None:
            self.notify("Not connected to the rig: press c on the Rig screen to connect.", severity="warning")
            return False
        refusal = self.sweep_refusal() if action != "stop" else ""
        if refusal:
            self.notify(refusal, title=f"{action} leg {', '.join(str(leg) for leg in legs)}", severity="warning")
            return False
        if action == "move":
            if move is None or len(legs) != 1:
                raise ValueError("a move is one leg's, with its MoveRequest")
            refusal = self.session.move_refusal()
            if refusal is not None:
                self.notify(refusal.say(RIG_KEYS), title=f"move leg {legs[0]}", severity="warning")
                return False
            self.session.begin_move(legs[0], move)
            self._rig_changed()
        self._rig_action_worker(self.rig, self.rig_lock, action, legs, move)
        return True

    @work(thread=True, group="rig-action", exit_on_error=False)
    def _rig_action_worker(self, rig, lock: threading.Lock, action: str, legs: tuple[int, ...],
                           move: MoveRequest | None = None) -> None:
        if action == "move":
            self._move_worker_body(rig, lock, legs[0], move)
            return
        try:
            rig_action(rig, lock, action, legs)
        except ActionRefused as exc:
            self.post_message(RigActionDone(action, legs, exc.say(RIG_KEYS)))
            return
        except Exception as exc:
            self.post_message(RigActionDone(action, legs, describe(exc, f"{action} failed")))
            return
        self.post_message(RigActionDone(action, legs))

    def _move_worker_body(self, rig, lock: threading.Lock, leg: int, move: MoveRequest) -> None:
        """The "move" action, on the rig-action worker: always ends with one RigMoveDone."""
        done = RigMoveDone(leg, "the move stopped before it began (see the log)")
        try:
            position, speed = checked_move(rig, lock, leg, move)
            done = RigMoveDone(leg, position_mm=position, speed_mm_s=speed)
        except MoveStopped as exc:
            done = RigMoveDone(leg, exc.say(RIG_KEYS), stopped=True)
        except ActionRefused as exc:
            done = RigMoveDone(leg, exc.say(RIG_KEYS))
        except Exception as exc:
            done = RigMoveDone(leg, describe(exc, f"move of leg {leg} failed"))
        finally:
            self.post_message(done)

    def on_rig_action_done(self, message: RigActionDone) -> None:
        legs = ", ".join(str(leg) for leg in message.legs)
        if message.error:
            self.notify(message.error, title=f"{message.action} leg {legs}", severity="error", timeout=12)
        else:
            if message.action == "enable":  # the quick stop is over: its toasts ("enable it (e)") go
                for leg in message.legs:
                    for notification in self._stop_notices.pop(leg, []):
                        if notification in self._notifications:
                            self._unnotify(notification)
            self.notify(f"{message.action}: leg {legs} done.", timeout=3)

    def on_rig_move_done(self, message: RigMoveDone) -> None:
        if message.error:
            self.session.end_move(message.leg, message.error)
            if message.stopped:  # kept, to be taken down when the leg is enabled again
                notification = Notification(message.error, f"move leg {message.leg}", "warning", 12)
                self._stop_notices.setdefault(message.leg, []).append(notification)
                self.post_message(Notify(notification))
            else:
                self.notify(message.error, title=f"move leg {message.leg}", severity="error", timeout=12)
        else:
            self.session.end_move(message.leg, f"leg {message.leg} at {message.position_mm:+.4f} mm "
                                               f"(moved at {message.speed_mm_s:g} mm/s)")
            self.notify(f"move: {self.rig_motion_text}.", timeout=3)
        self._rig_changed()
