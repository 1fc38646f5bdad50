"""A running job's messages taken in on the app's thread: its events folded into its SweepState, its end shown."""

from __future__ import annotations

from station.tui.bridge import SweepEnded, SweepEvent
from station.tui.error_text import describe
from station.tui.messages import ReplayRigOpened
from station.tui.state import EventNotice, SweepState, event_notice


def end_notice(s: SweepState) -> EventNotice:
    """The notification of the job `s` that ended without an error: how it ended, its points,
    where to go on (the Results page, finishing an aborted sweep later)."""
    written = s.out is not None and s.out.exists()  # no hint names a file never written
    resume = " Finish it later: r on the Sweep page (F2)." if s.label == "sweep" and written else ""
    note = {"completed": "completed." + (" Results: F3." if s.label == "sweep" else ""),
            "aborted": ("aborted; drives stopped, recording kept." if written else
                        "aborted before it began; nothing moved, nothing recorded.") + resume,
            "failed": f"failed: {s.reason}" + resume}.get(s.status, s.status)
    extra = f"; {s.note}" if s.note else ""
    return EventNotice(f"{s.label.capitalize()} {note} ({s.done} of {s.total} points){extra}", "Sweep",
                       "information" if s.status == "completed" else "warning", 8)


class JobEvents:
    """The app's part that takes in what a job's worker posts (station.tui.bridge): a message of a
    run that has ended already is dropped (`_runs`: run number -> its SweepState and on_done,
    filled by station.tui.job_dispatch). Assigns `replay_rig`, and quits after the job on show when
    asked to (`_quit_after_sweep`: station.tui.job_control). Uses of the app: `sweep`, `notify`,
    `exit`, `set_session`, `_sweep_changed` (station.tui.redraws)."""

    def on_replay_rig_opened(self, message: ReplayRigOpened) -> None:
        self.replay_rig = message.rig

    def on_sweep_event(self, message: SweepEvent) -> None:
        run = self._runs.get(message.run)
        if run is None:  # its job has ended already (an event after its end: nothing to show)
            return
        s = run[0]
        if s.apply(message.event) and s is self.sweep:
            self._sweep_changed()
        notice = event_notice(message.event, s.label)
        if notice is not None:
            self.notify(notice.text, title=notice.title, severity=notice.severity,  # type: ignore[arg-type]
                        timeout=notice.timeout)

    def on_sweep_ended(self, message: SweepEnded) -> None:
        run = self._runs.pop(message.run, None)
        if run is None:
            return
        s, done = run
        if s.active:  # no SweepFinished came: the run broke off with an exception
            s.status = "error" if message.error else message.outcome
            s.reason = message.error
        s.note = message.note
        s.result = message.result
        if s is self.sweep:
            self._sweep_changed()
        if message.error:
            self.notify(message.error, title="Sweep", severity="error", timeout=15)
        else:
            notice = end_notice(s)
            self.notify(notice.text, title=notice.title, severity=notice.severity,  # type: ignore[arg-type]
                        timeout=notice.timeout)
        if s.out is not None and s.out.exists():
            self.set_session(s.out)
        if done is not None:
            try:
                done(s)
            except Exception as exc:  # a follow-up must not take the app down
                self.notify(describe(exc, f"after the {s.label}"), severity="error", timeout=12)
        if self._quit_after_sweep and s is self.sweep:
            self.exit()
