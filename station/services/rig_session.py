"""One front end's rig: the connection, the lock discipline, the rig actions (enable, disable,
home, reset, stop) and the soft-limit-checked move, as plain Python.

The terminal UI keeps one `RigSession`; a web front end would keep one too. Threads are the
front end's business: the session's state (`rig`, `motion`, ...) is assigned on the front end's
own thread only, and the device I/O (`open_rig_for`, `rig_action`, `checked_move`,
`holding_rig`) runs on a worker that gets the rig and the lock as arguments, so it never reads
state that the front end's thread may be replacing.

The lock: a job (a sweep, a verification) holds it for its whole run; a rig action waits for it
a few seconds, then is refused ("busy"); a stop never waits (it must reach the drives while a
move or a job holds the lock).
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING

from station.services.config import StationConfig
from station.services.devices import DriveFault

if TYPE_CHECKING:  # the annotation only: the devices' modules load when the rig is opened
    from station.services.wiring import Rig

log = logging.getLogger("station.services.rig_session")

# A move or jog without a speed given runs at this fraction of the drive's maximum velocity
# (DriveLimits.max_velocity_mm_s).
JOG_SPEED_FRACTION = 0.25
# How long a rig action waits for the lock before it is refused as "busy", and a job.
ACTION_LOCK_WAIT_S = 5.0
JOB_LOCK_WAIT_S = 10.0
# Drive states a move is refused in, as the refusal names them (fault is refused separately).
_NOT_ENABLED_TEXT = {
    "switch_on_disabled": "disabled",
    "ready_to_switch_on": "switched off (ready to switch on)",
    "switched_on": "switched on but not enabled",
    "quick_stop_active": "quick-stopped",
    "not_ready": "not ready",
}


@dataclass(frozen=True)
class MoveRequest:
    """What a "move" rig action does: go to `target_mm`, or by `step_mm` from where the leg is
    (a jog), at `speed_mm_s` (None: JOG_SPEED_FRACTION of the drive's maximum velocity; more than
    the maximum is limited to it)."""

    target_mm: float | None = None
    step_mm: float | None = None
    speed_mm_s: float | None = None

    def describe(self) -> str:
        where = f"to {self.target_mm:+.3f} mm" if self.step_mm is None else f"by {self.step_mm:+g} mm"
        speed = f"{self.speed_mm_s:g} mm/s" if self.speed_mm_s else "the default speed"
        return f"{where} at {speed}"


REMEDIES = {"reset": "reset the fault", "enable": "enable it", "stop": "stop it"}
"""The rig actions a refusal may name as the way out; a front end names each its own way (the
terminal UI adds its key: station/tui/app.py), `say(how)`."""


class ActionRefused(Exception):
    """A rig action was refused before anything moved; the message says why and what to do.

    `template`: the message with the actions it names as the way out as {reset}, {enable},
    {stop} (REMEDIES): `say(how)` names them as a front end does them (how: action -> e.g. its
    key), str() in plain words."""

    def __init__(self, template: str) -> None:
        self.template = template
        super().__init__(self.say())

    def say(self, how: dict[str, str] | None = None) -> str:
        how = how or {}
        try:
            return self.template.format(**{action: text + (f" ({how[action]})" if action in how else "")
                                           for action, text in REMEDIES.items()})
        except (KeyError, IndexError, ValueError):  # a brace in an interpolated text: said as it is
            return self.template


class MoveStopped(ActionRefused):
    """A move was quick-stopped on its way (the message says where)."""


class RigBusy(ActionRefused):
    """The rig lock stayed taken (another action or a job holds the rig)."""


@contextlib.contextmanager
def holding_rig(lock: threading.Lock, timeout_s: float, busy: str):
    """Hold the rig `lock` for the block; RigBusy(`busy`) if it stays taken for `timeout_s`."""
    if not lock.acquire(timeout=timeout_s):
        raise RigBusy(busy)
    try:
        yield
    finally:
        lock.release()


def close_quietly(rig, what: str) -> None:
    """Close `rig` (None: nothing to close), logging instead of raising."""
    if rig is None:
        return
    try:
        rig.close()
    except Exception:
        log.exception(what)


def rig_action(rig, lock: threading.Lock, action: str, legs: tuple[int, ...]) -> None:
    """Run `action` (enable, disable, home, reset, stop) on `legs` of `rig`, under `lock` except
    a stop (which must never wait behind another transaction). ActionRefused (RigBusy) with the
    reason; a driver error as raised."""
    if action == "stop":
        for leg in legs:
            rig.axes[leg].stop()
        return
    with holding_rig(lock, ACTION_LOCK_WAIT_S, "the rig is busy (another action is running); try again"):
        for leg in legs:
            axis = rig.axes[leg]
            if action == "enable":
                if axis.status().fault:
                    raise ActionRefused(f"leg {leg} is in fault: {{reset}} first")
                axis.enable()
            elif action == "disable":
                axis.disable()
            elif action == "home":  # the reference is mid-stroke, 0 mm
                if not axis.status().enabled:
                    axis.enable()
                axis.move_to(0.0)
            elif action == "reset":
                axis.reset_fault()
            else:
                raise ActionRefused(f"unknown action {action!r}")


def checked_move(rig, lock: threading.Lock, leg: int, move: MoveRequest) -> tuple[float, float]:
    """The "move" rig action under `lock`: `move_axis` on `leg`; (position reached mm, speed mm/s)."""
    with holding_rig(lock, ACTION_LOCK_WAIT_S, "the rig is busy (another action is running); try again"):
        return move_axis(rig.axes[leg], leg, move)


def move_axis(axis, leg: int, move: MoveRequest) -> tuple[float, float]:
    """Check, then move one leg as `move` asks; (position reached mm, speed mm/s). Before any
    motion, ActionRefused with what to do for a leg in fault or not enabled, or a target beyond
    the drive's soft limits (the driver would refuse it too, with SoftLimitError); MoveStopped
    when a quick stop (Stop all, x) ended it on the way."""
    lim = axis.limits()
    st = axis.status()
    if st.fault:
        raise ActionRefused(f"leg {leg} is in fault: {{reset}}, then {{enable}}, first; nothing moved")
    if not st.enabled:
        state = _NOT_ENABLED_TEXT.get(str(st.state), str(st.state))
        raise ActionRefused(f"leg {leg} is {state}, not enabled: {{enable}} first; nothing moved")
    if move.step_mm is not None:
        target = st.position_mm + move.step_mm
        how = f" (a jog of {move.step_mm:+g} mm from {st.position_mm:+.3f} mm)"
    else:
        target, how = move.target_mm, ""
    if target is None or not math.isfinite(target) or not lim.min_mm <= target <= lim.max_mm:
        shown = f"{target:+.3f} mm" if isinstance(target, (int, float)) else repr(target)
        raise ActionRefused(f"leg {leg}: {shown}{how} is beyond the drive's soft limits {lim.min_mm:+.3f} .. "
                            f"{lim.max_mm:+.3f} mm; nothing moved")
    speed = move.speed_mm_s if move.speed_mm_s is not None else JOG_SPEED_FRACTION * lim.max_velocity_mm_s
    if not (math.isfinite(speed) and speed > 0):
        raise ActionRefused(f"leg {leg}: speed {speed:g} mm/s is not a speed > 0; nothing moved")
    speed = min(speed, lim.max_velocity_mm_s)
    try:
        reached = axis.move_to(target, velocity_mm_s=speed)
    except DriveFault:  # a quick stop ends move_to so: "not operation_enabled" (a timeout is a CommTimeout)
        try:
            now = axis.status()
        except Exception:
            now = None
        if now is not None and str(now.state) == "quick_stop_active":
            raise MoveStopped(f"leg {leg} was quick-stopped at {now.position_mm:+.3f} mm on its way to "
                              f"{target:+.3f} mm; {{enable}} to move again") from None
        raise
    return reached.position_mm, speed


class RigSession:
    """The rig of one front end: the connection (`rig`, `state`, `error`), the lock, the move
    under way (`motion`, leg -> MoveRequest) and how the last one ended (`motion_text`).

    Assigned on the front end's thread only: `detach` / `accept` / `fail` around a connect whose
    `open_rig_for` runs on a worker; `begin_move` / `end_move` around a `checked_move`."""

    def __init__(self, cfg: StationConfig, legs: tuple[int, ...], time_scale: float | None = None) -> None:
        self.cfg = cfg
        self.legs = tuple(legs)
        self.time_scale = time_scale
        self.rig: Rig | None = None  # once connected
        self.state = "not connected"  # "connecting" / "connected" / "not connected"
        self.error = ""
        self.lock = threading.Lock()
        self.motion: dict[int, MoveRequest] = {}
        self.motion_text = ""
        self._attempt = 0  # numbers the connect requests: only the newest one's rig is kept

    # -- connection ---------------------------------------------------------------------------
    def detach(self) -> tuple[object, int]:
        """Start a (re)connect: the current rig is detached (so `rig` never names a rig being
        closed); (the old rig for the worker to close, this attempt's number)."""
        old, self.rig = self.rig, None
        self._attempt += 1
        self.state, self.error = "connecting", ""
        return old, self._attempt

    def open_rig_for(self, old, lock: threading.Lock):
        """On a worker: close `old` (after any poll or action still using it), open the rig the
        config names. Raises what opening raises."""
        from station.services.wiring import open_rig  # here: a missing driver is the caller's message, not a crash

        with lock:
            close_quietly(old, "closing the previous rig failed")
            return open_rig(self.cfg, legs=self.legs, time_scale=self.time_scale)

    def accept(self, rig, attempt: int) -> bool:
        """A connect ended with `rig`: kept (True) if it is the newest attempt; else the caller
        closes it."""
        if attempt != self._attempt:
            return False
        self.rig = rig
        self.state, self.error = "connected", ""
        return True

    def fail(self, error: str, attempt: int) -> bool:
        """A connect failed with `error`: True if it was the newest attempt (now "not connected")."""
        if attempt != self._attempt:
            return False
        self.state, self.error = "not connected", error
        return True

    def close(self) -> None:
        rig, self.rig = self.rig, None
        close_quietly(rig, "closing the rig failed")

    def kind_text(self, hide_volatile: bool = False) -> str:
        if self.rig is None:
            return "no rig"
        if hide_volatile:
            return {"sim": "simulated rig", "live": "live rig", "replay": "replayed session"}.get(self.rig.kind,
                                                                                                 self.rig.kind)
        return self.rig.description

    # -- refusals, before a worker starts ----------------------------------------------------------
    def move_refusal(self) -> ActionRefused | None:
        """None when no move runs; else what a second move is refused with."""
        if not self.motion:
            return None
        leg, running = next(iter(self.motion.items()))
        return ActionRefused(f"Leg {leg} is still moving ({running.describe()}): wait for it, or {{stop}}.")

    def job_refusal(self) -> tuple[str, str]:
        """("", "") when a job may take the rig now; else (what stands in the way: "rig" or
        "motion", what is wrong): no rig connected, a move under way. (What a job itself refuses,
        a leg without a drive, its file, is the job's prepare: station/services/sweep_job.py.)"""
        if self.rig is None:
            return "rig", "Not connected to the rig"
        if self.motion:
            leg = next(iter(self.motion))
            return "motion", f"Leg {leg} is still moving"
        return "", ""

    def begin_move(self, leg: int, move: MoveRequest) -> None:
        self.motion[leg] = move
        self.motion_text = ""

    def end_move(self, leg: int, text: str) -> None:
        self.motion.pop(leg, None)
        self.motion_text = text
