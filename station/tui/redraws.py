"""Telling the screens on show what changed: the coalesced SweepChanged and RigStateChanged messages."""

from __future__ import annotations

import time

from station.tui.messages import RigStateChanged, SweepChanged


class Redraws:
    """The app's part that tells the screens to redraw; they never poll the app's state. Uses of
    the app: `screen_stack`, `set_timer`; owns `_sweep_redraw_due` and `_sweep_told_at` (assigned
    in StationApp.__init__, on the app's thread only)."""

    # The screens are told of sweep changes at most this often (s): a fast sweep folds many
    # events in between, and one redraw shows them all.
    SWEEP_REDRAW_S = 0.1

    def _sweep_changed(self) -> None:
        """`app.sweep` changed: post `SweepChanged` to the screens on show, at once when the last
        one is `SWEEP_REDRAW_S` old, else once at the end of that interval (a single one for
        every change in between)."""
        if self._sweep_redraw_due is not None:
            return  # one is due already; it shows this change too
        wait = self._sweep_told_at + self.SWEEP_REDRAW_S - time.monotonic()
        if wait <= 0:
            self._post_sweep_changed()
        else:
            self._sweep_redraw_due = self.set_timer(wait, self._post_sweep_changed, name="sweep-changed")

    def _post_sweep_changed(self) -> None:
        self._sweep_redraw_due = None
        self._sweep_told_at = time.monotonic()
        self._tell_screens(SweepChanged)

    def _rig_changed(self) -> None:
        """Tell the screens on show that the connection changed (the others redraw when shown)."""
        self._tell_screens(RigStateChanged)

    def _tell_screens(self, message_type: type) -> None:
        """Post a new `message_type()` to each screen of the current page's stack (a dialog and
        the page under it); a page not on show redraws when it is shown again."""
        try:
            screens = list(self.screen_stack)
        except Exception:  # no screen yet (the app is starting or has ended)
            return
        for screen in screens:
            screen.post_message(message_type())
