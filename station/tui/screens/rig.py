"""Rig screen: each leg's drive state, the interferometer and the environment, at a glance.

Status is read in a thread worker every `app.poll_interval_s` while this screen is shown and
no sweep holds the rig (a poll never waits for the rig: it skips a beat instead). The worker is
handed the rig and its lock, and posts what it read (`RigPolled`); it never writes the app's
state. The connection line is redrawn when the app says the connection or the sweep changed
(`RigStateChanged`, `SweepChanged`), not on a timer.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.message import Message
from textual.widgets import DataTable, Static

from drivers.interfaces import DriveStatus, Environment, Reading
from station.tui.errors import describe
from station.tui.messages import RigStateChanged, SweepChanged
from station.tui.screens.common import StationScreen

STATE_TEXT = {
    "operation_enabled": "[green]enabled[/green]",
    "switched_on": "switched on",
    "ready_to_switch_on": "ready",
    "switch_on_disabled": "disabled",
    "quick_stop_active": "[yellow]quick stop[/yellow]",
    "fault": "[red b]FAULT[/red b]",
    "not_ready": "[yellow]not ready[/yellow]",
}


@dataclass
class RigSnapshot:
    """One poll of the rig. Values or, per device, the sentence saying why it could not be read."""

    drives: dict[int, DriveStatus | str] = field(default_factory=dict)
    readings: dict[int, Reading | str] = field(default_factory=dict)
    environment: Environment | str | None = None
    laser_identity: str = ""
    fault_text: dict[int, str] = field(default_factory=dict)
    poll_ms: float = 0.0


class RigPolled(Message):
    """One poll of `rig` (the rig it was read from: a poll of a rig since replaced is not shown)."""

    def __init__(self, snapshot: RigSnapshot, rig=None) -> None:
        super().__init__()
        self.snapshot = snapshot
        self.rig = rig


class RigScreen(StationScreen):
    MODE = "rig"
    PAGE_HELP = "drive state per leg, interferometer, environment; select a leg row, then act on it"
    BINDINGS = [
        Binding("c", "app.connect", "Connect"),
        Binding("e", "leg_action('enable')", "Enable"),
        Binding("d", "leg_action('disable')", "Disable"),
        Binding("h", "leg_action('home')", "Home (0 mm)"),
        Binding("r", "leg_action('reset')", "Reset fault"),
        Binding("x", "stop_all", "Stop all"),
    ]

    def compose(self) -> ComposeResult:
        yield from self.compose_header()
        with Vertical(id="rig-body"):
            yield Static("", id="rig-connection")
            table = DataTable(id="drives", cursor_type="row", zebra_stripes=True)
            yield table
            yield Static("", id="laser")
            yield Static("", id="environment")
        yield from self.compose_footer()

    def on_mount(self) -> None:
        table = self.query_one("#drives", DataTable)
        table.add_columns("Leg", "State", "Position mm", "Moving", "Foll. err um", "Load N", "Table", "Fault")
        for leg in self.app.legs:
            table.add_row(str(leg), "–", "–", "–", "–", "–", "–", "–", key=str(leg))
        self.snapshot: RigSnapshot | None = None
        self._show_connection()
        self.set_interval(max(self.app.poll_interval_s, 0.05), self._tick)  # the devices' status

    def on_screen_resume(self) -> None:
        self._show_connection()

    def on_rig_state_changed(self, message: RigStateChanged) -> None:
        self._show_connection()

    def on_sweep_changed(self, message: SweepChanged) -> None:
        self._show_connection()

    # -- polling ---------------------------------------------------------------------------------
    def _tick(self) -> None:
        app = self.app
        if app.screen is not self or app.rig is None or app.sweep.active:
            return
        self._poll(app.rig, app.rig_lock)

    @work(thread=True, exclusive=True, group="poll", exit_on_error=False)
    def _poll(self, rig, lock) -> None:
        if not lock.acquire(blocking=False):
            return  # busy (a sweep, an action, a reconnect): skip this beat
        t0 = time.monotonic()
        snap = RigSnapshot()
        try:
            for leg, axis in sorted(rig.axes.items()):
                try:
                    st = snap.drives[leg] = axis.status()
                    if st.fault and rig.profile is not None:
                        snap.fault_text[leg] = rig.profile.fault_text(st.fault_code)
                except Exception as exc:
                    snap.drives[leg] = describe(exc)
            try:
                snap.laser_identity = rig.laser.identity()
                snap.environment = rig.laser.environment()
            except Exception as exc:
                snap.environment = describe(exc)
            else:
                for leg in sorted(rig.axes):
                    try:
                        snap.readings[leg] = rig.laser.read(leg)
                    except Exception as exc:
                        snap.readings[leg] = describe(exc)
        finally:
            lock.release()
        snap.poll_ms = (time.monotonic() - t0) * 1000.0
        self.post_message(RigPolled(snap, rig))

    def on_rig_polled(self, message: RigPolled) -> None:
        if message.rig is not self.app.rig:  # read from a rig since detached (a reconnect)
            return
        self.snapshot = message.snapshot
        self._show_snapshot(message.snapshot)

    # -- drawing ---------------------------------------------------------------------------------
    def _show_connection(self) -> None:
        app = self.app
        widget = self.query_one("#rig-connection", Static)
        if app.rig_state == "connected":
            text = f"[green]●[/green] connected: {app._rig_kind_text()}"
            if app.sweep.active:
                text += "   [yellow]sweep running: status polling paused (see Sweep, F2)[/yellow]"
            elif self.snapshot is not None and not app.hide_volatile:
                text += f"   [dim]last poll {self.snapshot.poll_ms:.0f} ms[/dim]"
        elif app.rig_state == "connecting":
            text = "[yellow]●[/yellow] connecting…"
        else:
            text = "[red]●[/red] not connected — press [b]c[/b] to connect"
            if app.rig_error:
                text += f"\n[red]{app.rig_error}[/red]"
        widget.update(text)

    def _show_snapshot(self, snap: RigSnapshot) -> None:
        table = self.query_one("#drives", DataTable)
        for leg in self.app.legs:
            st = snap.drives.get(leg)
            if st is None:
                cells = ["not connected", "–", "–", "–", "–", "–", "–"]
            elif isinstance(st, str):
                cells = ["[red]no answer[/red]", "–", "–", "–", "–", "–", st[:60]]
            else:
                cells = [
                    STATE_TEXT.get(st.state, st.state),
                    f"{st.position_mm:+9.4f}",
                    "yes" if st.moving else "no",
                    f"{st.following_error_um:+7.2f}",
                    f"{st.load_n:7.1f}",
                    f"bank {st.active_bank} {'on' if st.table_enabled else 'off'}",
                    f"[red]{snap.fault_text.get(leg) or f'code 0x{st.fault_code:04X}'}[/red]" if st.fault else "–",
                ]
            for col, value in enumerate(cells, start=1):
                table.update_cell_at((table.get_row_index(str(leg)), col), value, update_width=True)
        laser = self.query_one("#laser", Static)
        parts = []
        for leg, r in sorted(snap.readings.items()):
            if isinstance(r, str):
                parts.append(f"leg {leg}: [red]beam?[/red]")
            else:
                beam = "[green]beam ok[/green]" if r.beam_ok else "[red]beam broken[/red]"
                parts.append(f"leg {leg}: {beam} {r.signal_pct:3.0f} %")
        ident = snap.laser_identity or "interferometer"
        laser.update(f"[b]{ident}[/b]\n" + ("   ".join(parts) if parts else "no readings"))
        env = snap.environment
        widget = self.query_one("#environment", Static)
        if isinstance(env, Environment):
            mats = "  ".join(f"leg {i + 1} {t:.2f}" for i, t in enumerate(env.material_temp_c))
            widget.update(f"air {env.air_temp_c:.2f} °C   {env.air_pressure_hpa:.1f} hPa   "
                          f"{env.humidity_pct:.1f} %RH\nmaterial °C: {mats}")
        elif isinstance(env, str):
            widget.update(f"[red]environment unreadable:[/red] {env}")
        self._show_connection()

    # -- actions ---------------------------------------------------------------------------------
    def selected_leg(self) -> int:
        table = self.query_one("#drives", DataTable)
        return self.app.legs[max(table.cursor_row, 0)]

    def action_leg_action(self, action: str) -> None:
        self.app.rig_action(action, (self.selected_leg(),))

    def action_stop_all(self) -> None:
        if self.app.sweep.active:
            self.app.action_abort_sweep()
        elif self.app.rig is not None:
            self.app.rig_action("stop", tuple(sorted(self.app.rig.axes)))
