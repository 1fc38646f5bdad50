"""Rig screen: each leg's drive state, the interferometer and the environment, at a glance;
moving one leg to a position at a speed, or jogging it by a step.

Status is read in a thread worker every `app.poll_interval_s` while this screen is shown and
no sweep holds the rig (a poll never waits for the rig: it skips a beat instead). The worker is
handed the rig and its lock, and posts what it read (`RigPolled`); it never writes the app's
state. The connection line is redrawn when the app says the connection or the sweep changed
(`RigStateChanged`, `SweepChanged`), not on a timer.

Moves and jogs go through the app's `rig_action("move", ...)` (a worker; refused while a sweep
holds the rig, on a leg in fault or not enabled, and beyond the drive's soft limits); the
page checks what it can first (the numbers typed, the soft limits of the last poll). Stop all
(x) quick-stops a move at once, also while typing in the move fields.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from rich.markup import escape
from textual.message import Message
from textual.widgets import Button, DataTable, Input, Label, Select, Static

from station.services.devices import DriveLimits, DriveStatus, Environment, Reading
from procedures.vocabulary import InputError
from station import values
from station.tui.error_text import describe
from station.tui.fields import ValueField
from station.tui.messages import RigStateChanged, SweepChanged
from station.tui.screens.common import ConfirmScreen, StationScreen
from station.tui.widgets import set_columns, wrap_items

DRIVE_COLUMNS = ("Leg", "State", "Position mm", "Moving", "Foll. err um", "Load N", "Table", "Fault")
NARROW_DRIVE_COLUMNS = ("Leg", "State", "Pos. mm", "Moving", "Foll. µm", "Load N", "Table", "Fault")

STATE_TEXT = {
    "operation_enabled": "[green]enabled[/green]",
    "switched_on": "switched on",
    "ready_to_switch_on": "ready",
    "switch_on_disabled": "disabled",
    "quick_stop_active": "[yellow]quick stop[/yellow]",
    "fault": "[red b]FAULT[/red b]",
    "not_ready": "[yellow]not ready[/yellow]",
}
JOG_STEPS_MM = (0.1, 1.0, 10.0)
# The page's actions that move a leg or choose how it moves: their keys act only when no value
# field has the focus (RigScreen.check_action). Stop all (x) is not one: it acts everywhere.
MOTION_ACTIONS = frozenset({"move", "jog", "next_step", "leg_action"})


def target_kind(lim: DriveLimits | None, leg: int = 0) -> values.Kind:
    """A motion target's kind: a position (station.values.POSITION_MM, the command line's)
    within leg `leg`'s soft limits `lim` when they have been read (the refusal names them)."""
    if lim is None:
        return values.POSITION_MM
    kind = values.POSITION_MM.bounded(max(lim.min_mm, values.POSITION_MM.lo), min(lim.max_mm, values.POSITION_MM.hi))
    return replace(kind, name=f"a position within leg {leg}'s soft limits")


class MoveField(ValueField):
    """A number field of the move bar (a ValueField: read by the kind's parser, every character
    typed kept). It does not claim the x key (a number has no x), so Stop all (x, a priority key
    of the page) acts while the technician types a target."""

    def check_consume_key(self, key: str, character: str | None) -> bool:
        return key != "x" and super().check_consume_key(key, character)


@dataclass
class RigSnapshot:
    """One poll of the rig. Values or, per device, the sentence saying why it could not be read."""

    drives: dict[int, DriveStatus | str] = field(default_factory=dict)
    limits: dict[int, DriveLimits] = field(default_factory=dict)
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
    snapshot: RigSnapshot | None = None  # the last poll shown
    PAGE_HELP = "drive state per leg, interferometer, environment; select a leg row, then act on it: enable, move, jog; x stops"
    # the keys that act on the rig act only when pressed on their own (StationScreen.RIG_KEYS)
    RIG_KEYS = frozenset({"connect", "leg_action", "move", "jog"})
    BINDINGS = [
        Binding("c", "connect", "Connect"),
        Binding("e", "leg_action('enable')", "Enable"),
        Binding("d", "leg_action('disable')", "Disable"),
        Binding("h", "leg_action('home')", "Home (0 mm)"),
        Binding("r", "leg_action('reset')", "Reset fault"),
        # priority (and the move fields do not claim x): stops also while typing a target
        Binding("x", "stop_all", "Stop all", priority=True),
        Binding("m", "move", "Move to"),
        Binding("plus,equals_sign", "jog(1)", "Jog +", key_display="+"),
        Binding("minus", "jog(-1)", "Jog −", key_display="-"),
        Binding("j", "next_step", "Jog step"),
    ]

    def compose(self) -> ComposeResult:
        yield from self.compose_header()
        with Vertical(id="rig-body"):
            yield Static("", id="rig-connection")
            table = DataTable(id="drives", cursor_type="row", zebra_stripes=True)
            yield table
            with Horizontal(id="move-bar"):  # the move and the jog: one row, or two on a narrow terminal
                with Horizontal(id="move-to", classes="move-group"):
                    yield Label("leg 1", id="move-leg")
                    yield Label(" to ")
                    yield MoveField("", id="move-target", kind=values.POSITION_MM, where="leg 1 target", blank=None,
                                    placeholder="target", compact=True,
                                    tooltip="target position, mm (0 = mid-stroke, a decimal point: 1.5); Enter moves")
                    yield Label(" mm at ")
                    yield MoveField("", id="move-speed", kind=values.SPEED_MM_S, where="speed", blank=None,
                                    placeholder="default", compact=True,
                                    tooltip="speed, mm/s; blank: a safe fraction of the drive's maximum")
                    yield Label(" mm/s ")
                    yield Button("Move (m)", id="move", compact=True, variant="primary")
                with Horizontal(id="move-jog", classes="move-group"):
                    yield Label("   jog ", id="jog-label")
                    yield Button("− (-)", id="jog-minus", compact=True)
                    yield Select([(f"{step:g} mm", step) for step in JOG_STEPS_MM], value=1.0, allow_blank=False,
                                 id="jog-step", compact=True, tooltip="jog step (j: next)")
                    yield Button("+ (+)", id="jog-plus", compact=True)
                    yield Button("Stop (x)", id="stop", compact=True, variant="error")
            yield Static("", id="move-status")
            yield Static("", id="laser")
            yield Static("", id="environment")
        yield from self.compose_footer()

    def on_mount(self) -> None:
        self._drives_columns()
        self.snapshot: RigSnapshot | None = None
        self._show_connection()
        self._show_motion()
        self.set_interval(max(self.app.poll_interval_s, 0.05), self._tick)  # the devices' status

    def on_screen_resume(self) -> None:
        self._show_connection()
        self._show_motion()

    def on_rig_state_changed(self, message: RigStateChanged) -> None:
        self._show_connection()
        self._show_motion()
        if not self.app.rig_motion:
            self._tick()  # a move ended (or the rig changed): show where the legs are now

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
                    snap.limits[leg] = axis.limits()  # read once by the driver, then cached
                    st = snap.drives[leg] = axis.status()
                    if st.fault:  # the drive's own text of its fault code (ServoAxis.fault_text)
                        snap.fault_text[leg] = axis.fault_text(st.fault_code)
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
                text += f"   [yellow]{app.sweep.label} {app.sweep.status}: status polling paused (see Sweep, F2)[/yellow]"
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
        self._show_readings(snap)
        self._show_connection()
        self._show_motion()

    def _show_readings(self, snap: RigSnapshot) -> None:
        """The interferometer's beam per leg and the environment, lines broken between legs (the
        width of the terminal: a narrow one gets more lines, never a leg cut in two)."""
        width = max(self.app.size.width - 4, 20)  # the body's padding, a scroll bar
        laser = self.query_one("#laser", Static)
        parts = []
        for leg, r in sorted(snap.readings.items()):
            if isinstance(r, str):
                parts.append(f"leg {leg}: [red]beam?[/red]")
            else:
                beam = "[green]beam ok[/green]" if r.beam_ok else "[red]beam broken[/red]"
                parts.append(f"leg {leg}: {beam} {r.signal_pct:3.0f} %")
        ident = snap.laser_identity or "interferometer"
        laser.update(f"[b]{ident}[/b]\n" + (wrap_items(parts, width) if parts else "no readings"))
        env = snap.environment
        widget = self.query_one("#environment", Static)
        if isinstance(env, Environment):
            mats = ["material °C:", *(f"leg {i + 1} {t:.2f}" for i, t in enumerate(env.material_temp_c))]
            widget.update(f"air {env.air_temp_c:.2f} °C   {env.air_pressure_hpa:.1f} hPa   "
                          f"{env.humidity_pct:.1f} %RH\n" + wrap_items(mats, width, "  "))
        elif isinstance(env, str):
            widget.update(f"[red]environment unreadable:[/red] {env}")

    def _drives_columns(self) -> None:
        """The drives table's columns, shorter labels on a narrow terminal (so a leg's state, a
        quick stop say, still leaves the fault column on show); its rows anew, the cursor kept."""
        table = self.query_one("#drives", DataTable)
        row = table.cursor_row
        if set_columns(table, NARROW_DRIVE_COLUMNS if self.narrow else DRIVE_COLUMNS):
            for leg in self.app.legs:
                table.add_row(str(leg), "–", "–", "–", "–", "–", "–", "–", key=str(leg))
            table.move_cursor(row=max(row, 0))

    def size_changed(self) -> None:
        self._drives_columns()
        if self.snapshot is not None:  # the drives again; the readings' lines broken for the new width
            self._show_snapshot(self.snapshot)

    def _show_motion(self) -> None:
        """The move bar's leg, default speed and the line under it: what Enter would do (the
        target typed, with the leg's soft limits, before anything moves) or why it is refused,
        the move under way, or the leg's soft limits and how the last move ended."""
        from station.services.rig_session import JOG_SPEED_FRACTION

        app = self.app
        leg = self.selected_leg()
        self.query_one("#move-leg", Label).update(f"[b]leg {leg}[/b]")
        lim = self.snapshot.limits.get(leg) if self.snapshot is not None else None
        speed = self.query_one("#move-speed", MoveField)
        target = self.query_one("#move-target", MoveField)
        # the target's kind: a position within this leg's soft limits once they are read (the
        # worker checks them on the drive again before it moves)
        target.set_kind(target_kind(lim, leg), f"leg {leg} target")
        if lim is not None:
            speed.placeholder = f"{JOG_SPEED_FRACTION * lim.max_velocity_mm_s:g}"
            limits_short = f"soft limits {lim.min_mm:+.3f} .. {lim.max_mm:+.3f} mm"
            limits = (f"leg {leg}: {limits_short}, max {lim.max_velocity_mm_s:g} "
                      f"mm/s (blank speed: {JOG_SPEED_FRACTION * lim.max_velocity_mm_s:g} mm/s)")
        else:
            speed.placeholder = "default"
            limits_short = "soft limits not read yet: the drive checks them before it moves"
            limits = (f"leg {leg}: soft limits not read yet (blank speed: {JOG_SPEED_FRACTION:.0%} of the drive's "
                      "maximum)")
        preview = self.move_preview(leg, limits_short)
        if app.rig_motion:
            moving = "; ".join(f"leg {n} moving {m.describe()}" for n, m in app.rig_motion.items())
            text = f"[yellow b]{moving}…[/yellow b]  x stops it"
        elif preview:
            text = preview + (f"\n[dim]last move:[/dim] {app.rig_motion_text}" if app.rig_motion_text else "")
        elif app.rig_motion_text:
            text = f"{limits}\n[dim]last move:[/dim] {app.rig_motion_text}"
        else:
            text = limits
        self.query_one("#move-status", Static).update(text)

    def move_preview(self, leg: int, limits_text: str) -> str:
        """The line shown while a target is typed: what Enter (or m) would do, "leg 1 → +1.500 mm
        at 5 mm/s (soft limits -95.000 .. +95.000 mm)", or the refusal of the target or speed
        typed (red, the parser's message naming the field and what to type). '' when both are
        blank."""
        target = self.query_one("#move-target", MoveField)
        speed = self.query_one("#move-speed", MoveField)
        if not target.value.strip() and not speed.value.strip():
            return ""
        refused = [r for r in (target.refusal, speed.refusal) if r]
        if refused:
            return "[red]" + escape("; ".join(refused)) + "[/red]"
        position, mm_s = target.read(), speed.read()
        at = f"at {mm_s:g} mm/s" if mm_s is not None else "at the default speed"
        if position is None:
            return f"leg {leg}: type a target in mm to move it {at} ({limits_text})"
        return f"[b]leg {leg} → {position:+.3f} mm[/b] {at} ({limits_text}): Enter or m moves it"

    def on_input_changed(self, event: Input.Changed) -> None:
        if event.input.id in ("move-target", "move-speed"):
            self._show_motion()

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        if event.data_table.id == "drives":
            self._show_motion()

    # -- actions ---------------------------------------------------------------------------------
    def selected_leg(self) -> int:
        table = self.query_one("#drives", DataTable)
        return self.app.legs[max(table.cursor_row, 0)]

    def move_request(self, step_mm: float | None = None):
        """The MoveRequest the fields ask for (a jog by `step_mm` when given), read by the
        fields' parsers (the command line's: station.values; the target within the last poll's
        soft limits); InputError saying what is wrong. The worker checks the target against the
        drive again."""
        from station.services.rig_session import MoveRequest

        self._show_motion()  # the target's kind for the leg selected now
        leg = self.selected_leg()
        speed = self.query_one("#move-speed", MoveField).read()
        lim = self.snapshot.limits.get(leg) if self.snapshot is not None else None
        if speed is not None and lim is not None and speed > lim.max_velocity_mm_s:
            self.notify(f"{speed:g} mm/s is above the drive's maximum: leg {leg} moves at "
                        f"{lim.max_velocity_mm_s:g} mm/s.", title=f"move leg {leg}", severity="warning")
        if step_mm is not None:
            return MoveRequest(step_mm=step_mm, speed_mm_s=speed)
        target = self.query_one("#move-target", MoveField).read()
        if target is None:
            raise InputError("type a target position in mm (0 = mid-stroke), then press Enter or m")
        return MoveRequest(target_mm=target, speed_mm_s=speed)

    def _start_move(self, step_mm: float | None = None) -> None:
        """Start the move (or jog) the fields ask for. The focus stays where it is: a target typed
        and entered leaves the cursor in its field, so the next one typed goes there too (never
        to the motion keys; x stops from the fields as well)."""
        leg = self.selected_leg()
        try:
            move = self.move_request(step_mm)
        except InputError as exc:  # said next to the fields too (move_preview)
            self.notify(escape(f"{exc}; nothing moved"), title=f"move leg {leg}", severity="error", timeout=10)
            if step_mm is None and not self.query_one("#move-target", Input).value.strip():
                self.query_one("#move-target", Input).focus()  # the digits typed next go there
            return
        self.app.rig_action("move", (leg,), move)

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        """The keys that move a leg (or change how it moves) act only from the rig panel, never
        while a value field has the focus (a `-` of "-25" is the field's, not a jog). None: shown
        dimmed in the footer meanwhile. Buttons and Enter in a field call the actions directly."""
        if action in MOTION_ACTIONS and isinstance(self.focused, Input):
            return None
        return True

    def action_move(self) -> None:
        self._start_move()

    def action_jog(self, sign: int) -> None:
        step = float(self.query_one("#jog-step", Select).value)
        self._start_move(step_mm=sign * step)

    def action_next_step(self) -> None:
        select = self.query_one("#jog-step", Select)
        now = float(select.value)
        select.value = JOG_STEPS_MM[(JOG_STEPS_MM.index(now) + 1) % len(JOG_STEPS_MM)] if now in JOG_STEPS_MM else 1.0

    def on_input_submitted(self, event: Input.Submitted) -> None:
        if event.input.id in ("move-target", "move-speed"):
            event.stop()
            self.action_move()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        if event.button.id == "move":
            self.action_move()
        elif event.button.id == "jog-minus":
            self.action_jog(-1)
        elif event.button.id == "jog-plus":
            self.action_jog(1)
        elif event.button.id == "stop":
            self.action_stop_all()

    def action_connect(self) -> None:
        """Connect; when connected, reconnecting asks first: it closes the connection to every
        drive and the interferometer (the simulated rig starts afresh, its legs disabled)."""
        app = self.app
        if app.rig is None or app.sweep.active:  # not connected: nothing to lose (a sweep: the app refuses)
            app.action_connect()
            return
        sim = getattr(app.rig, "sim", None) is not None
        question = ("[b]Reconnect to the rig?[/b]\n\nThe connection to the drives and the interferometer is closed "
                    "and opened again" + ("; the simulated rig starts afresh: its legs disabled, at 0 mm." if sim
                                          else "; the drives are asked their state anew."))
        self.app.push_screen(ConfirmScreen(question, yes="Reconnect", no="Cancel"),
                             lambda yes: app.action_connect() if yes else None)

    def action_leg_action(self, action: str) -> None:
        self.app.rig_action(action, (self.selected_leg(),))

    def action_stop_all(self) -> None:
        if self.app.sweep.active:
            self.app.action_abort_sweep()
        elif self.app.rig is not None:
            self.app.rig_action("stop", tuple(sorted(self.app.rig.axes)))
