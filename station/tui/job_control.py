"""Pause, resume and abort of the job on show (the one place the UI asks for each), and quitting while it runs."""

from __future__ import annotations

from textual import work

from station.tui.screens.common import ConfirmScreen

# How long quitting waits for an aborted sweep to stop the drives and close its recording.
QUIT_WAIT_S = 15.0


class JobControl:
    """The app's part that asks the job on show (`sweep`, its RunControl `sweep_control`) to pause,
    resume or abort; the status shown follows the procedure's Paused / Resumed / SweepFinished
    events (SweepState.apply), not the request. Assigns `_quit_after_sweep` (StationApp.__init__;
    station.tui.job_events quits when the job has ended). Uses of the app: `notify`, `push_screen`,
    `exit`, `_sweep_idle` (station.tui.job_dispatch), `_sweep_changed` (station.tui.redraws)."""

    def _control_of_running_sweep(self):
        if not self.sweep.active or self.sweep_control is None:
            self.notify("No sweep is running.", severity="warning")
            return None
        return self.sweep_control

    def action_pause_sweep(self) -> None:
        """Pause between points (nothing moves while paused), or resume: the one place the UI
        asks for either. The status on show changes when the procedure has paused or resumed
        (its Paused / Resumed events, folded in by on_sweep_event), not here."""
        control = self._control_of_running_sweep()
        if control is None or self.sweep.status == "aborting":
            return
        if control.paused:
            control.resume()
            self.notify("Resuming the sweep.", timeout=3)
        else:
            control.pause()
            self.notify("Pausing after the current point…", timeout=3)

    def action_abort_sweep(self) -> None:
        """Abort: quick-stop the axes now (from a worker, the UI stays live), end the sweep. The
        one place the UI asks for an abort (the Rig page's stop-all and quitting come here too);
        the status shows "aborting" (SweepState.request_abort) until SweepFinished says how it ended."""
        control = self._control_of_running_sweep()
        if control is None:
            return
        if self.sweep.request_abort():
            self._sweep_changed()
            self._abort_worker(control)
            self.notify("Aborting: stopping the drives…", severity="warning", timeout=4)

    @work(thread=True, group="abort", exit_on_error=False)
    def _abort_worker(self, control) -> None:
        control.abort("aborted by the operator")

    def _abort_on_close(self) -> None:
        """The last line of defence (e.g. the terminal closed): abort a running job and wait for its
        worker to return. Not through action_abort_sweep: no worker starts and nothing is drawn any
        more, so the abort is sent from here and waited for."""
        if self.sweep_control is not None and not self._sweep_idle.is_set():
            self.sweep_control.abort("the station UI closed")
            self._sweep_idle.wait(QUIT_WAIT_S)

    # -- quitting --------------------------------------------------------------------------------
    async def action_quit(self) -> None:
        if self._quit_after_sweep:
            return
        if self.sweep.active:
            legs = ", ".join(str(leg) for leg in self.sweep.legs)

            def confirmed(yes: bool | None) -> None:
                if yes and not self.sweep.active:  # it ended while the question was open
                    self.exit()
                elif yes:
                    self._quit_after_sweep = True
                    self.action_abort_sweep()
                    self.notify("Stopping the drives and closing the recording, then quitting…", timeout=10)

            self.push_screen(
                ConfirmScreen(
                    f"A {self.sweep.label} is running on leg {legs}.\n\nQuit anyway? It is aborted, the drives "
                    "are stopped and disabled, and the recording is kept"
                    + (f" (finish it later with r on the Sweep page, or `station sweep --resume {self.sweep.out}`)."
                       if self.sweep.label == "sweep" and self.sweep.out is not None and self.sweep.out.exists()
                       else "."),
                    yes="Abort and quit", no="Keep sweeping",
                ),
                confirmed,
            )
            return
        self.exit()
