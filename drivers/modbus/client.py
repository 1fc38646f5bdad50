"""Modbus client for the leg servo drives: a shared bus and one `ServoAxis` per leg.

`ModbusBus` wraps a pymodbus sync client (TCP or RTU) with one lock (six axes share one bus),
a transaction counter, the silence between frames the slowest drive on the line needs, requests
split to the length a drive accepts, and errors a technician can act on: `CommTimeout` names
the URL, unit id and timeout. `ModbusServoAxis` implements `drivers.interfaces.ServoAxis` on the
register map of a `DriveProfile` (docs/register-map.md, docs/drive-profiles.md): its unit id,
request lengths, word order and scaling come from the profile. A move is one write
(controlword with new-set-point + target) plus status reads until the drive reports the target
reached: two transactions when the drive arrives at once (simulated rig at time scale 0). A
drive whose controlword and target are not contiguous gets the target first, then the
controlword (`[protocol] move_write`), and one whose set-point latches on a rising edge gets
the new-set-point bit cleared after the move is acknowledged (`set_point_latch = "edge"`).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Callable, Sequence
from urllib.parse import parse_qs, urlsplit

from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException

from drivers.clock import SystemClock
from drivers.errors import CommTimeout, DriveFault, DriverError, FramingError, SoftLimitError, TableError
from drivers.interfaces import Clock, DriveLimits, DriveStatus, TableBank, TableSpec
from drivers.modbus.codec import chunks, crc16_modbus, int_range
from drivers.modbus.profile import MAX_READ_WORDS, MAX_WRITE_WORDS, DriveProfile
from drivers.modbus.wire import READ_DEVICE_ID, READ_HOLDING, READ_WRITE_MULTIPLE, WRITE_MULTIPLE, WireTally
from drivers.states import DriveState

log = logging.getLogger(__name__)

EXCEPTION_NAMES = {
    1: "illegal function",
    2: "illegal data address",
    3: "illegal data value",
    4: "server device failure",
    5: "acknowledge",
    6: "server device busy",
    8: "memory parity error",
    10: "gateway path unavailable",
    11: "gateway target failed to respond",
}


class BusConfigError(DriverError, ValueError):
    """A drive URL or bus setting is malformed."""

    hint = "Use tcp://HOST:PORT (e.g. tcp://127.0.0.1:5020) or rtu:///dev/ttyUSB0?baud=115200."


class RequestRefused(DriverError):
    """The drive answered a request with a Modbus exception (it refused it)."""

    hint = ""

    def __init__(self, message: str, exception_code: int, address: int):
        super().__init__(message)
        self.exception_code = exception_code
        self.address = address


class ModbusBus:
    """One Modbus line (a TCP connection or a serial port) shared by several drives.

    Thread-safe: one request at a time. `timeout_s` bounds one request including its
    retries (each attempt waits timeout_s / (retries + 1)). `transactions` counts requests
    sent (each write chunk and each read is one). `on_request(kind, unit, address, count)` is
    called before each request ("read"/"write"), e.g. for tracing. `min_frame_gap_s`: silence
    kept between the end of one exchange (reply or failure) and the next request, in real
    seconds (`require_gap`: the largest any drive on the line asks for). `wire` tallies the
    RTU frame bytes of every request and reply (drivers.modbus.wire, for the wire-time model).
    """

    def __init__(self, client, where: str, timeout_s: float, retries: int):
        self._client = client
        self.where = where
        self.timeout_s = timeout_s
        self.retries = retries
        self.transactions = 0
        self.wire = WireTally()
        self.on_request: Callable[[str, int, int, int], None] | None = None
        self.min_frame_gap_s = 0.0
        self._last_frame_end = -math.inf  # time.monotonic() when the last exchange ended
        self._lock = threading.RLock()
        self._users = 0

    def require_gap(self, gap_s: float) -> None:
        """Keep at least `gap_s` seconds of silence between frames (a drive's manual asks for it)."""
        with self._lock:
            self.min_frame_gap_s = max(self.min_frame_gap_s, float(gap_s))

    # -- construction -------------------------------------------------------------------------------
    @staticmethod
    def _check(timeout_s: float, retries: int) -> float:
        if not (isinstance(timeout_s, (int, float)) and timeout_s > 0 and math.isfinite(timeout_s)):
            raise BusConfigError(f"timeout must be a positive number of seconds, got {timeout_s!r}")
        if not (isinstance(retries, int) and 0 <= retries <= 10):
            raise BusConfigError(f"retries must be an integer 0..10, got {retries!r}")
        return timeout_s / (retries + 1)

    @classmethod
    def tcp(cls, host: str, port: int, timeout_s: float = 1.0, retries: int = 1) -> "ModbusBus":
        """Modbus TCP to `host`:`port`; connects on the first request."""
        attempt_s = cls._check(timeout_s, retries)
        client = ModbusTcpClient(host, port=int(port), timeout=attempt_s, retries=retries,
                                 reconnect_delay=0.0, reconnect_delay_max=attempt_s)
        return cls(client, f"tcp://{host}:{port}", timeout_s, retries)

    @classmethod
    def rtu(cls, port: str, baudrate: int = 115200, timeout_s: float = 1.0, retries: int = 1) -> "ModbusBus":
        """Modbus RTU on serial `port` (8N1 at `baudrate`); opens on the first request."""
        attempt_s = cls._check(timeout_s, retries)
        client = ModbusSerialClient(port, baudrate=int(baudrate), bytesize=8, parity="N", stopbits=1,
                                    timeout=attempt_s, retries=retries, reconnect_delay=0.0,
                                    reconnect_delay_max=attempt_s)
        return cls(client, f"rtu://{port}?baud={baudrate}", timeout_s, retries)

    @classmethod
    def from_url(cls, url: str, timeout_s: float = 1.0, retries: int = 1) -> "ModbusBus":
        """A bus for `tcp://HOST:PORT` (port default 502) or `rtu:///dev/PATH?baud=115200`."""
        try:
            parts = urlsplit(url)
        except ValueError as exc:
            raise BusConfigError(f"drive URL {url!r} is malformed ({exc}).") from None
        if parts.scheme == "tcp":
            try:
                port = parts.port or 502
            except ValueError:
                raise BusConfigError(f"drive URL {url!r}: the port must be a number 1..65535.") from None
            if not parts.hostname:
                raise BusConfigError(f"drive URL {url!r} has no host.")
            return cls.tcp(parts.hostname, port, timeout_s, retries)
        if parts.scheme == "rtu":
            path = (parts.netloc + parts.path) if parts.netloc else parts.path
            if not path:
                raise BusConfigError(f"drive URL {url!r} has no serial port path.")
            query = parse_qs(parts.query)
            try:
                baud = int(query.get("baud", ["115200"])[0])
            except ValueError:
                raise BusConfigError(f"drive URL {url!r}: baud must be a number.") from None
            return cls.rtu(path, baud, timeout_s, retries)
        raise BusConfigError(f"drive URL {url!r}: unknown scheme {parts.scheme!r}.")

    # -- sharing ----------------------------------------------------------------------------------------
    def acquire(self) -> None:
        with self._lock:
            self._users += 1

    def release(self) -> None:
        """One user is done; the connection closes when the last one is (it reopens on demand)."""
        with self._lock:
            self._users = max(0, self._users - 1)
            if self._users == 0:
                self.close()

    def close(self) -> None:
        with self._lock:
            try:
                self._client.close()
            except Exception:  # closing a dead link must not raise
                log.debug("closing %s failed", self.where, exc_info=True)

    # -- requests ------------------------------------------------------------------------------------
    def _wait_gap(self) -> None:
        """Sleep until the line has been silent for `min_frame_gap_s` (real time: a line's property)."""
        if self.min_frame_gap_s > 0:
            wait = self._last_frame_end + self.min_frame_gap_s - time.monotonic()
            while wait > 0:
                time.sleep(wait)
                wait = self._last_frame_end + self.min_frame_gap_s - time.monotonic()

    def _execute(self, kind: str, unit: int, address: int, count: int, call, frame: tuple[int, int, int]):
        """One request: `frame` = (function, read words, write words) for the wire tally."""
        with self._lock:
            self._wait_gap()
            if self.on_request:
                self.on_request(kind, unit, address, count)
            self.transactions += 1
            try:
                rsp = call()
            except ModbusException as exc:
                self.close()  # a late reply must not be taken for the next request's
                if isinstance(exc, ConnectionException):
                    if "closed" in str(exc):
                        what = "the drive closed the connection"
                    else:
                        what = "cannot connect (refused or unreachable)"
                else:
                    what = f"no answer within {self.timeout_s:g} s ({self.retries + 1} attempt(s))"
                raise CommTimeout(f"drive at {self.where}, unit id {unit}: {what} while trying to {kind} "
                                  f"register {address} (+{count}).") from None
            except OSError as exc:
                self.close()
                raise CommTimeout(f"drive at {self.where}, unit id {unit}: {exc.strerror or exc} while trying to "
                                  f"{kind} register {address} (+{count}).") from None
            finally:
                self._last_frame_end = time.monotonic()
            self.wire.add(*frame, refused=rsp.isError())
            if rsp.isError():
                code = int(getattr(rsp, "exception_code", 0))
                name = EXCEPTION_NAMES.get(code, "unknown exception")
                raise RequestRefused(f"drive at {self.where}, unit id {unit} refused to {kind} register {address} "
                                     f"(+{count}): Modbus exception {code} ({name}).", code, address)
            return rsp

    def read(self, unit: int, address: int, count: int, max_words: int = MAX_READ_WORDS) -> list[int]:
        """Read `count` holding registers, in requests of at most `max_words` (the drive's limit;
        Modbus' own is 125)."""
        max_words = max(1, min(int(max_words), MAX_READ_WORDS))
        out: list[int] = []
        for a, n in ((address + i, min(max_words, count - i)) for i in range(0, count, max_words)):
            rsp = self._execute("read", unit, a, n,
                                lambda a=a, n=n: self._client.read_holding_registers(a, count=n, device_id=unit),
                                (READ_HOLDING, n, 0))
            self._check_function(rsp, 3, "read", unit, a, n)
            regs = list(rsp.registers)
            if len(regs) != n:
                raise CommTimeout(f"drive at {self.where}, unit id {unit}: asked for {n} registers at {a}, got {len(regs)}.")
            out += regs
        return out

    def write(self, unit: int, address: int, values: Sequence[int], max_words: int = MAX_WRITE_WORDS) -> None:
        """Write holding registers, in requests of at most `max_words` (the drive's limit;
        Modbus' own is 123)."""
        max_words = max(1, min(int(max_words), MAX_WRITE_WORDS))
        for a, vals in chunks(address, list(values), max_words):
            rsp = self._execute("write", unit, a, len(vals),
                                lambda a=a, vals=vals: self._client.write_registers(a, vals, device_id=unit),
                                (WRITE_MULTIPLE, 0, len(vals)))
            self._check_function(rsp, 16, "write", unit, a, len(vals))

    def read_device_identification(self, unit: int) -> dict[int, str]:
        """Modbus Read Device Identification (function 43, MEI type 14), the basic objects: object
        id -> text (0 VendorName, 1 ProductCode, 2 MajorMinorRevision). RequestRefused when the
        drive answers with an exception (01: it does not implement the function)."""
        rsp = self._execute("read device identification (43/14) of", unit, 0, 3,
                            lambda: self._client.read_device_information(read_code=1, object_id=0, device_id=unit),
                            (READ_DEVICE_ID, 0, 0))
        self._check_function(rsp, 0x2B, "read device identification of", unit, 0, 3)
        return {int(oid): (v if isinstance(v, bytes) else b"".join(v)).decode("ascii", "replace").strip()
                for oid, v in rsp.information.items()}
    def write_read(self, unit: int, write_address: int, values: Sequence[int], read_address: int, count: int) -> list[int]:
        """Write `values` and then read `count` registers in one transaction (function 23,
        read/write multiple registers: the drive does the write first). Only for a drive whose
        profile says it serves function 23 and for requests within its lengths (the caller's
        part: nothing is split here)."""
        rsp = self._execute("write+read", unit, write_address, len(values),
                            lambda: self._client.readwrite_registers(read_address=read_address, read_count=count,
                                                                     write_address=write_address, values=list(values),
                                                                     device_id=unit),
                            (READ_WRITE_MULTIPLE, count, len(values)))
        self._check_function(rsp, 23, "write+read", unit, write_address, len(values))
        regs = list(rsp.registers)
        if len(regs) != count:
            raise CommTimeout(f"drive at {self.where}, unit id {unit}: asked for {count} registers at {read_address}, got {len(regs)}.")
        return regs

    def _check_function(self, rsp, expected: int, kind: str, unit: int, address: int, count: int) -> None:
        """pymodbus matches a reply to its request by transaction id only: a reply of another
        function (line noise, a confused gateway) would be taken for the answer. Refused, and the
        connection closed so that nothing else of that exchange is read as the next reply."""
        got = getattr(rsp, "function_code", expected)
        if got != expected:
            self.close()
            raise CommTimeout(f"drive at {self.where}, unit id {unit}: answered a request to {kind} register {address} "
                              f"(+{count}) with Modbus function {got}, not {expected}.")


MOVE_TIMEOUT_FACTOR = 2.0
MOVE_TIMEOUT_MARGIN_S = 1.0
"""The default move timeout is MOVE_TIMEOUT_FACTOR times the trapezoid time of the move plus
MOVE_TIMEOUT_MARGIN_S, in seconds of the axis' clock: the clock the drive's motion runs on (the
rig's virtual clock on the simulated rig, where one second lasts `time_scale` real seconds, so
this margin is 20 ms of real time at scale 0.02). The margin is for the drive (settling, a
profile a little slower than the one read). The station's own delays are not counted against
it: `move_to` starts the timeout once the drive has acknowledged the move and judges a "not
reached" by when that status was asked for, not by when the answer was looked at, so a late
reply or a process busy drawing cannot turn into a timeout."""


PLAUSIBLE_LOAD_N = 1e6
"""|axial load| no leg carries (hexapod legs are rated tens of kN): a status reporting more was
garbled on the way (Modbus TCP frames carry no checksum of their own), so `status()` refuses it
as a FramingError and the caller reads again, rather than record a value that makes the session
file unreadable (its reader refuses loads beyond 10 MN as damage)."""


class ModbusServoAxis:
    """One leg's drive on a `ModbusBus` (unit id: `unit_id` if given, else the profile's
    `[protocol] unit_ids`, by default the leg number).

    Implements `drivers.interfaces.ServoAxis`. Positions are mm in leg coordinates (as the drive
    reports them: compensated), errors um (measured minus commanded). `clock` paces the status
    polling (`poll_interval_s` between reads while moving) and measures move timeouts: it must be
    the clock the drive's motion runs on (the rig's clock on the simulated rig);
    `move_timeout_s` None = twice the trapezoid time of the move plus 1 s (MOVE_TIMEOUT_FACTOR,
    MOVE_TIMEOUT_MARGIN_S).
    """

    def __init__(
        self,
        bus: ModbusBus,
        leg: int,
        profile: DriveProfile | None = None,
        clock: Clock | None = None,
        poll_interval_s: float = 0.001,
        move_timeout_s: float | None = None,
        unit_id: int | None = None,
    ):
        self.bus = bus
        self.leg = int(leg)
        self.profile = profile or DriveProfile.load()
        self.unit = int(unit_id if unit_id is not None else self.profile.protocol.unit_id(leg))
        if not 1 <= self.unit <= 247:
            raise BusConfigError(f"leg {leg}: unit id {self.unit} is outside 1..247.")
        self.clock = clock or SystemClock()
        self.poll_interval_s = poll_interval_s
        self.move_timeout_s = move_timeout_s
        self._limits: DriveLimits | None = None
        self._profile_motion: tuple[float, float] | None = None  # profile velocity, accel
        self._last_position_mm: float | None = None
        self._trace: tuple | None = None  # move_traced: (interval s, [(t s, position mm)])
        self.trace_round_trips_s: list[float] = []  # the last traced move's polls: response - request, s
        self._closed = False
        p = self.profile
        self._proto = p.protocol
        self._move_block = p.blocks.get("move_command")
        self._target_reg = p.registers["target_position"]
        self._pr = p.control == "pr_trigger"  # servo-on parameter + path trigger, no controlword
        if not self._pr:
            self._cw_addr = p.address("controlword")
            # `move` in [commands] when the drive wants more than new-set-point (Kinco: 0x3F, bit 5
            # "change set immediately" too)
            self._move_cw = p.commands.get("move", p.commands["enable_operation"] | (1 << p.controlword_bits["new_set_point"]))
        # Function 23 for a move: the move's write and the status read after it in one
        # transaction, where the profile says the drive serves it, the move is one write and
        # the status one request (else the usual write, then reads).
        status_runs = p.runs(p.blocks["status"].names)
        self._move_and_status = (self._proto.read_write_multiple and not self._pr and self._proto.move_write == "single"
                                 and self._move_block is not None and len(status_runs) == 1
                                 and self._move_block.words <= self._proto.max_write_words)
        self._status_run = status_runs[0]
        self._status_decode = p.run_decoder(self._status_run[2])
        self._sw_decoded: dict[int, tuple[DriveState, bool]] = {}
        bus.require_gap(self._proto.min_frame_gap_ms / 1000.0)
        bus.acquire()

    def __repr__(self) -> str:
        return f"ModbusServoAxis(leg={self.leg}, unit={self.unit}, {self.bus.where})"

    # -- reading ------------------------------------------------------------------------------------
    def _read_names(self, names: Sequence[str]) -> dict:
        """Values of registers `names`: contiguous ones share a request, none longer than the
        drive accepts, no value split across two requests."""
        p = self.profile
        out = {}
        for address, words, regs in p.runs(names):
            got = self.bus.read(self.unit, address, words, self._proto.max_read_words)
            for n in regs:
                r = p.registers[n]
                out[n] = r.decode(got[r.address - address : r.end - address])
        return out

    def _read_block(self, name: str) -> dict:
        b = self.profile.blocks.get(name)
        return self._read_names(b.names) if b else {}

    def _write(self, address: int, words: Sequence[int]) -> None:
        self.bus.write(self.unit, address, words, self._proto.max_write_words)

    def identity(self) -> str:
        """'vendor product s/n SERIAL fw FIRMWARE' as the drive reports it; for a drive without
        identity registers, the profile's vendor and product and the unit id, said as such."""
        v = self._read_block("identity")
        if not {"vendor", "product", "serial", "firmware"} <= set(v):
            ident = self.profile.identity
            return (f"{ident['vendor']} {ident['product']} unit {self.unit} (identity from profile "
                    f"{self.profile.name}; the drive has no identity registers)")
        return f"{v['vendor']} {v['product']} s/n {v['serial']} fw {v['firmware']}"

    def drive_identity(self) -> dict:
        """The drive's identity for the session (procedures/io/recording/identity.py): vendor,
        product_code, revision from Read Device Identification (43/14) when the profile says the
        drive answers it (`[protocol] device_identification`), source "modbus-device-id"; else the
        profile's [identity] vendor and product, source "config". The serial from the drive's
        identity registers when it has them, else None (the config may give it)."""
        ident = self.profile.identity
        out = {"vendor": ident.get("vendor") or None, "product_code": ident.get("product") or None,
               "revision": None, "serial": None, "source": "config"}
        if self._proto.device_identification:
            objects = self.bus.read_device_identification(self.unit)
            out.update(vendor=objects.get(0) or None, product_code=objects.get(1) or None,
                       revision=objects.get(2) or None, source="modbus-device-id")
        if self.profile.has("serial"):
            out["serial"] = str(self._read_names(["serial"])["serial"]).strip() or None
        return out

    def check_map_version(self) -> None:
        """Refuse a drive whose register map version differs from the profile's. A drive without a
        map-version register (a real drive) is checked by reading its statusword instead: it must
        answer at the profile's address."""
        if not self.profile.has("map_version"):
            self._read_names(["statusword"])
            return
        v = self._read_block("identity")
        if v["map_version"] != self.profile.map_version:
            raise DriveFault(f"leg {self.leg}: the drive at {self.bus.where} unit {self.unit} reports register map "
                             f"version {v['map_version']}, the profile {self.profile.path} is for version "
                             f"{self.profile.map_version}.", hint="Use the drive profile that matches the drive's firmware.")

    def fault_text(self, code: int) -> str:
        """The profile's text of fault `code` (ServoAxis.fault_text)."""
        return self.profile.fault_text(code)

    def limits(self, refresh: bool = False) -> DriveLimits:
        """Soft travel limits and motion limits as the drive reports them (read once, cached);
        a limit the profile maps to no register is the profile's [limits] value."""
        if self._limits is None or refresh:
            lim = self.profile.limits
            v = {"soft_limit_min": lim.soft_min_mm, "soft_limit_max": lim.soft_max_mm,
                 "max_velocity": lim.max_velocity_mm_s, "max_acceleration": lim.max_accel_mm_s2,
                 "profile_velocity": lim.profile_velocity_mm_s, "profile_acceleration": lim.profile_accel_mm_s2}
            v.update(self._read_block("limits"))
            self._limits = DriveLimits(v["soft_limit_min"], v["soft_limit_max"], v["max_velocity"], v["max_acceleration"])
            self._profile_motion = (min(v["profile_velocity"], v["max_velocity"]), min(v["profile_acceleration"], v["max_acceleration"]))
        return self._limits

    def _status_from(self, v: dict) -> DriveStatus:
        p = self.profile
        load = v.get("axial_load", math.nan)
        if not math.isfinite(v["position_actual"]) or abs(load) > PLAUSIBLE_LOAD_N:
            raise FramingError(f"leg {self.leg}: the drive at {self.bus.where} unit {self.unit} reported an impossible "
                               f"status (position {v['position_actual']} mm, axial load {load} N): a reply garbled "
                               "on the link; read it again.")
        sw = v["statusword"]
        decoded = self._sw_decoded.get(sw)
        if decoded is None:  # a statusword takes a few values: each decoded once
            decoded = self._sw_decoded[sw] = (p.state_of(sw), p.sw_bit(sw, "target_reached"))
        state, reached = decoded
        self._last_position_mm = v["position_actual"]
        # registers a drive does not have: not measured (NaN), no code, no table
        return DriveStatus(
            state=state,
            fault=state is DriveState.FAULT,
            fault_code=v.get("fault_code", 0),
            moving=not reached,
            target_reached=reached,
            position_mm=v["position_actual"],
            following_error_um=v.get("following_error", math.nan),
            load_n=v.get("axial_load", math.nan),
            active_bank=v.get("active_bank", 0),
            table_enabled=bool(v.get("table_enable", 0)),
        )

    def status(self) -> DriveStatus:
        """One read of the status block."""
        return self._status_from(self._read_block("status"))

    def _decode_status_run(self, words: list[int]) -> DriveStatus:
        return self._status_from(self._status_decode(words))

    # -- state machine ------------------------------------------------------------------------------
    def _command(self, name: str) -> None:
        self._write(self._cw_addr, [self.profile.commands[name]])

    def _set_param(self, register: str, command: str) -> None:
        """pr_trigger drives: write [commands] `command` to register `register`."""
        r = self.profile.registers[register]
        self._write(r.address, r.encode(self.profile.commands[command]))

    def enable(self) -> None:
        """Walk the CiA 402 state machine to operation enabled. DriveFault if the drive is in
        fault (reset it first) or does not get there."""
        st = self.status()
        if st.fault:
            raise DriveFault(f"leg {self.leg}: the drive is in fault {self.profile.fault_text(st.fault_code)}; "
                             f"reset the fault before enabling.", st.fault_code)
        if st.enabled:
            return
        if self._pr:
            self._set_param("servo_on", "servo_on")
            st = self.status()
            if not st.enabled:
                raise DriveFault(f"leg {self.leg}: the drive did not switch the servo on (state {st.state}, alarm "
                                 f"0x{st.fault_code:04X}).", st.fault_code)
            return
        if self._proto.mode_of_operation is not None:
            # profile position mode before the power stage comes on (CiA 402 6060h)
            r = self.profile.registers["modes_of_operation"]
            self._write(r.address, r.encode(self._proto.mode_of_operation))
        seq = {
            DriveState.QUICK_STOP_ACTIVE: ["enable_operation"],
            DriveState.SWITCHED_ON: ["enable_operation"],
            DriveState.READY_TO_SWITCH_ON: ["switch_on", "enable_operation"],
        }.get(st.state, ["shutdown", "switch_on", "enable_operation"])
        for cmd in seq:
            self._command(cmd)
        st = self.status()
        if not st.enabled:
            raise DriveFault(f"leg {self.leg}: the drive did not enable (state {st.state}, fault code 0x{st.fault_code:04X}).",
                             st.fault_code)

    def disable(self) -> None:
        """Power stage off (CiA 402 disable voltage -> switch on disabled; servo off)."""
        if self._pr:
            self._set_param("servo_on", "servo_off")
            return
        self._command("disable_voltage")

    def reset_fault(self) -> None:
        """Clear a drive fault (rising edge of the fault-reset bit; on a pr_trigger drive, servo
        off and the alarm-reset write); DriveFault if it persists."""
        if self._pr:
            self._set_param("servo_on", "servo_off")
            self._set_param("fault_code", "alarm_reset")
        else:
            self._command("disable_voltage")
            self._command("fault_reset")
        st = self.status()
        if st.fault:
            raise DriveFault(f"leg {self.leg}: the fault {self.profile.fault_text(st.fault_code)} persists after reset.",
                             st.fault_code)

    def stop(self) -> None:
        """Quick stop (a pr_trigger drive: stop the path, then servo off, so that as after a
        CiA 402 quick stop the axis is not enabled). Never raises: after a fault or with a dead
        link it only logs."""
        try:
            if self._pr:
                self._set_param("pr_trigger", "stop_path")
                self._set_param("servo_on", "servo_off")
                return
            self._command("quick_stop")
        except Exception as exc:  # the caller is making the rig safe; it cannot act on this
            log.warning("leg %s: quick stop not delivered: %s", self.leg, exc)

    # -- motion ------------------------------------------------------------------------------------
    def _trapezoid_s(self, distance_mm: float) -> float:
        v, a = self._profile_motion or (self._limits.max_velocity_mm_s, self._limits.max_accel_mm_s2)  # type: ignore[union-attr]
        d = abs(distance_mm)
        return 2 * math.sqrt(d / a) if d <= v * v / a else v / a + d / v

    def move_to(self, target_mm: float, timeout_s: float | None = None,
                velocity_mm_s: float | None = None) -> DriveStatus:
        """Move to `target_mm` (leg coordinates) and return the status once the drive reports
        the target reached.

        SoftLimitError before anything is written when the target lies outside the limits the
        drive reports; DriveFault when the drive faults or is not enabled; CommTimeout when it
        does not answer, or does not arrive within `timeout_s` (default: `move_timeout_s`, or
        twice the trapezoid time plus 1 s) on this axis' clock, counted from the drive's
        acknowledgement of the move to the asking of a status that still says not arrived.

        `velocity_mm_s`: the profile velocity for this move only (`_move_at`), limited to the
        drive's maximum; None moves at the drive's profile velocity as it stands.
        """
        if velocity_mm_s is not None:
            return self._move_at(target_mm, timeout_s, velocity_mm_s)
        lim = self.limits()
        if not (isinstance(target_mm, (int, float)) and math.isfinite(target_mm)):
            raise SoftLimitError(f"leg {self.leg}: target {target_mm!r} is not a finite position in mm; nothing moved.")
        if not lim.min_mm <= target_mm <= lim.max_mm:
            raise SoftLimitError(f"leg {self.leg}: target {target_mm:.4f} mm is outside the soft limits "
                                 f"{lim.min_mm:.3f} .. {lim.max_mm:.3f} mm reported by the drive; nothing moved.")
        if timeout_s is None:
            timeout_s = self.move_timeout_s
        if timeout_s is None:
            span = lim.max_mm - lim.min_mm
            dist = abs(target_mm - self._last_position_mm) if self._last_position_mm is not None else span
            timeout_s = MOVE_TIMEOUT_FACTOR * self._trapezoid_s(dist) + MOVE_TIMEOUT_MARGIN_S
        trace = self._trace
        try:
            first = self._write_move(target_mm, with_status=trace is None)
        except RequestRefused as exc:
            raise DriveFault(f"leg {self.leg}: the drive refused the move to {target_mm:.4f} mm: {exc}", 0) from None
        # Judged on the clock the motion runs on, and only on the drive's time: from the write's
        # acknowledgement (the drive began the move no later than its reply) to the asking of a
        # status (the drive reports its state no earlier than that). Measuring from before the
        # write to after the reply counted the station's delays as motion time: on the simulated
        # rig at time scale 0.02 a reply looked at 60 ms late (the UI drawing) is 3 s on its clock.
        t0 = self.clock.now()
        while True:
            asked = self.clock.now()
            if trace is not None and not self._trace_poll(trace, target_mm):
                if asked - t0 > timeout_s:
                    self.stop()
                    raise CommTimeout(f"leg {self.leg}: the drive did not reach {target_mm:.4f} mm within "
                                      f"{timeout_s:.3g} s (at {trace[1][-1][1]:.4f} mm); it was quick-stopped.")
                self.clock.sleep(trace[0])
                continue
            st, first = (first, None) if first is not None else (self.status(), None)
            if st.fault:
                raise DriveFault(f"leg {self.leg}: drive fault {self.profile.fault_text(st.fault_code)} "
                                 f"on the move to {target_mm:.4f} mm.", st.fault_code)
            if not st.enabled:
                raise DriveFault(f"leg {self.leg}: the drive is {st.state}, not operation_enabled, so it did not move "
                                 f"to {target_mm:.4f} mm; enable it first.", 0,
                                 hint="Enable the axis (it may have been quick-stopped or disabled).")
            if st.target_reached:
                return st
            if asked - t0 > timeout_s:
                self.stop()
                raise CommTimeout(f"leg {self.leg}: the drive did not reach {target_mm:.4f} mm within {timeout_s:.3g} s "
                                  f"(at {st.position_mm:.4f} mm); it was quick-stopped.",
                                  hint="Check the mechanics and the drive's motion profile.")
            self.clock.sleep(self.poll_interval_s)

    def move_traced(self, target_mm: float, velocity_mm_s: float, interval_s: float = 0.02,
                    timeout_s: float | None = None) -> tuple[DriveStatus, list[tuple[float, float]]]:
        """`move_to(target_mm, velocity_mm_s=...)` that polls position actual every `interval_s`
        of the axis' clock while the drive moves: returns the status on arrival and the trace,
        (time s, position mm) per poll, the time the middle of the request on this axis' clock
        (the clock a streaming laser's samples are stamped on: on-the-fly with a laser without
        trigger input, docs/onthefly.md). Position actual alone is read while moving (one
        register, a short request); the status block once it stands still (arrived, stopped
        or faulted), judged as `move_to` judges it."""
        if not interval_s > 0:
            raise ValueError(f"leg {self.leg}: trace interval {interval_s!r} is not > 0 s")
        self._trace = (float(interval_s), [])
        self.trace_round_trips_s = []
        try:
            st = self.move_to(target_mm, timeout_s, velocity_mm_s)
            return st, self._trace[1]
        finally:
            self._trace = None

    def poll_position(self) -> tuple[float, float, float]:
        """One read of position actual alone, as a traced move polls it: (request sent, response
        in, on the axis' clock, s; position mm). The round trip is the second less the first; a
        traced move stamps the position at their middle (bench/bench_latency.py measures both)."""
        t_a = self.clock.now()
        pos = self._read_names(("position_actual",))["position_actual"]
        return t_a, self.clock.now(), float(pos)

    def _trace_poll(self, trace, target_mm: float) -> bool:
        """One position poll of a traced move; True once the status should be read (the position
        at the target, or the same as the poll before: the drive stands still)."""
        t_a, t_b, pos = self.poll_position()
        self.trace_round_trips_s.append(t_b - t_a)
        points = trace[1]
        # standing still: after it moved (a jerk-limited start moves less than a count at first),
        # or not started half a second after the move was commanded (refused, faulted, stalled)
        moved = bool(points) and any(p != points[0][1] for _, p in points)
        still = (moved and pos == points[-1][1]) or (bool(points) and t_b - points[0][0] > 0.5 and not moved)
        points.append((0.5 * (t_a + t_b), float(pos)))
        count_mm = self.profile.registers["position_actual"].scale or 1e-6  # one count
        return still or abs(pos - target_mm) <= 2 * count_mm

    def _write_move(self, target_mm: float, with_status: bool = True) -> DriveStatus | None:
        """Command the move: one write of controlword + target where the profile's move_command
        block allows it; else the target first and then the controlword (the drive latches the
        target it holds when the set-point bit arrives). A drive latching on the rising edge
        gets the bit cleared once the move has been accepted, ready for the next one.
        Returns the status read with the move's write (function 23, `_move_and_status`), or
        None when the status is still to be read."""
        target = self._target_reg.encode(target_mm)
        if self._pr:
            # the path's target first, then the trigger that runs the path
            self._write(self._target_reg.address, target)
            self._set_param("pr_trigger", "run_path")
            return None
        st = None
        if self._proto.move_write == "single":
            b = self._move_block
            words = [0] * b.words
            words[self._cw_addr - b.start] = self._move_cw
            a = self._target_reg.address - b.start
            words[a : a + len(target)] = target
            if self._move_and_status and with_status:
                address, count, _ = self._status_run
                st = self._decode_status_run(self.bus.write_read(self.unit, b.start, words, address, count))
            else:
                self._write(b.start, words)
        else:
            self._write(self._target_reg.address, target)
            self._write(self._cw_addr, [self._move_cw])
        if self._proto.set_point_latch == "edge":
            self._command("enable_operation")
        return st

    def _move_at(self, target_mm: float, timeout_s: float | None, velocity_mm_s: float) -> DriveStatus:
        """`move_to` at `velocity_mm_s` (limited to the drive's maximum): the profile velocity
        register is written before the move and the drive's own value written back after it,
        however the move ends, so later moves (a sweep) keep the drive's profile. A target
        `move_to` refuses is refused before anything is written."""
        if not (isinstance(velocity_mm_s, (int, float)) and math.isfinite(velocity_mm_s) and velocity_mm_s > 0):
            raise ValueError(f"leg {self.leg}: velocity {velocity_mm_s!r} is not a speed > 0 mm/s; nothing moved.")
        lim = self.limits()
        if not (isinstance(target_mm, (int, float)) and math.isfinite(target_mm) and lim.min_mm <= target_mm <= lim.max_mm):
            return self.move_to(target_mm, timeout_s)  # SoftLimitError, nothing written
        reg = self.profile.registers.get("profile_velocity")
        if reg is None:
            raise DriveFault(f"leg {self.leg}: the drive profile {self.profile.name} maps no profile velocity register, "
                             f"so a move at {velocity_mm_s:g} mm/s cannot be commanded; nothing moved.", 0,
                             hint="Move at the drive's own speed (no velocity), or map profile_velocity in the profile.")
        before = reg.decode(self.bus.read(self.unit, reg.address, reg.words, self._proto.max_read_words))
        motion = self._profile_motion
        v = min(float(velocity_mm_s), lim.max_velocity_mm_s)
        self._write(reg.address, reg.encode(v))
        if motion is not None:
            self._profile_motion = (v, motion[1])  # the default timeout follows this move's speed
        try:
            return self.move_to(target_mm, timeout_s)
        finally:
            self._profile_motion = motion
            try:
                self._write(reg.address, reg.encode(before))
            except Exception as exc:  # the move's own outcome (or exception) matters more
                log.warning("leg %s: profile velocity %.3f mm/s not written back: %s", self.leg, before, exc)

    # -- position compare (on-the-fly capture, docs/onthefly.md) ---------------------------------
    def arm_position_compare(self, start_mm: float, step_mm: float, count: int) -> None:
        """Arm the position-compare output: a pulse each time position actual passes
        `start_mm + i * step_mm` (i < `count`) in the direction of the step's sign; count 0
        switches it off. One write of the profile's `compare` block. DriverError when the
        drive's profile has no compare registers."""
        if "compare" not in self.profile.blocks:
            raise DriverError(f"leg {self.leg}: the drive profile {self.profile.name} has no position-compare "
                              "registers (block `compare`), so on-the-fly capture is not possible; use a "
                              "stop-and-go plan")
        values = {"compare_start": float(start_mm), "compare_step": float(step_mm), "compare_count": int(count)}
        b = self.profile.blocks["compare"]
        words: list[int] = []
        for name in b.names:
            words += self.profile.registers[name].encode(values[name])
        self.bus.write(self.unit, b.start, words)

    # -- compensation tables ------------------------------------------------------------------------
    def _no_table(self) -> TableError:
        return TableError(f"leg {self.leg}: the drive (profile {self.profile.name}) holds no compensation table: "
                          f"{self.profile.table_note}",
                          hint="Compensate in the station or in the motion controller instead (docs/compensation.md).")

    def _check_bank(self, bank: int) -> None:
        if self.profile.table is None:
            raise self._no_table()
        if bank not in range(self.profile.table.banks):
            raise TableError(f"leg {self.leg}: table bank {bank!r} does not exist (banks are 0..{self.profile.table.banks - 1}).",
                             hint="")

    def table_spec(self) -> TableSpec | None:
        """The table this drive holds (its profile's [table] section); None when it holds none."""
        return table_spec(self.profile)

    def active_bank(self) -> int:
        """The bank the drive applies (0 or 1); TableError for a drive without tables."""
        if self.profile.table is None:
            raise self._no_table()
        r = self.profile.registers["active_bank"]
        return r.decode(self.bus.read(self.unit, r.address, r.words, self._proto.max_read_words))

    def read_table(self, bank: int) -> TableBank:
        """The table held in `bank`. TableError if the bank's entries do not match its checksum
        (e.g. an interrupted push left it half written)."""
        self._check_bank(bank)
        t = self.profile.table
        base = t.bank_base[bank]
        mx = self._proto.max_read_words
        h = t.decode_header(self.bus.read(self.unit, base, t.header_words, mx))
        n = h["point_count"]
        if n > t.max_points:
            raise TableError(f"leg {self.leg}: bank {bank} claims {n} points, more than the drive's {t.max_points}.", hint="")
        fwd = self.bus.read(self.unit, t.fwd_address(bank), n, mx) if n else []
        rev = self.bus.read(self.unit, t.rev_address(bank), n, mx) if n else []
        crc = crc16_modbus(fwd + rev)
        if crc != h["checksum"] or h["units"] != t.units_code:
            raise TableError(f"leg {self.leg}: bank {bank} holds an inconsistent table (header checksum 0x{h['checksum']:04X}, "
                             f"entries 0x{crc:04X}, units code {h['units']}); an interrupted push?", hint="")
        to_um = lambda ws: tuple((w - 0x10000 if w & 0x8000 else w) * t.entry_scale_um for w in ws)  # noqa: E731
        return TableBank(h["start_position"], h["spacing"], to_um(fwd), to_um(rev), h["checksum"])

    def write_table(self, bank: int, table: TableBank) -> None:
        """Write `table` into the inactive `bank`: entries in requests as long as the drive
        accepts, the header (with the checksum) last, then read everything back and compare.

        Refuses (TableError, before writing) a bank that is active, a table the drive cannot
        hold (points, spacing, corrections beyond the profile's limits), or a given checksum
        that does not match the entries. Does not activate: call `activate_table(bank)`.
        """
        self._check_bank(bank)
        fwd, rev, header = table_registers(self.profile, table, where=f"leg {self.leg}")
        active = self.active_bank()
        if bank == active:
            raise TableError(f"leg {self.leg}: bank {bank} is the active table; write bank {1 - bank} and activate it.")
        t = self.profile.table
        base = t.bank_base[bank]
        # the header (with the checksum) goes last, so a bank is consistent only once complete
        runs = _writable_runs(self.profile, header)
        plan = [(t.fwd_address(bank), fwd), (t.rev_address(bank), rev)] + [(base + off, words) for off, words in runs]
        try:
            for address, words in plan:
                if words:
                    self._write(address, words)
        except RequestRefused as exc:
            raise TableError(f"leg {self.leg}: the drive refused the table write to bank {bank}: {exc}") from None
        except CommTimeout as exc:
            raise CommTimeout(f"leg {self.leg}: table push to bank {bank} interrupted: {exc}",
                              hint="The previously active table is still active; push again when the drive answers.") from None
        # read back and compare
        mx = self._proto.max_read_words
        got_h = self.bus.read(self.unit, base, t.header_words, mx)
        got_f = self.bus.read(self.unit, t.fwd_address(bank), len(fwd), mx) if fwd else []
        got_r = self.bus.read(self.unit, t.rev_address(bank), len(rev), mx) if rev else []
        for what, want, got, a0 in (("forward entries", fwd, got_f, t.fwd_address(bank)),
                                    ("reverse entries", rev, got_r, t.rev_address(bank))):
            if want != got:
                i = next(i for i, (x, y) in enumerate(zip(want, got)) if x != y)
                raise TableError(f"leg {self.leg}: read-back of bank {bank} {what} differs at register {a0 + i}: "
                                 f"wrote {want[i]}, read {got[i]}; the bank was not activated.")
        for off, words in runs:
            if got_h[off : off + len(words)] != words:
                raise TableError(f"leg {self.leg}: read-back of bank {bank} header differs (wrote {words}, read "
                                 f"{got_h[off:off + len(words)]}); the bank was not activated.")
        valid = t.header["valid"].decode(got_h[t.header["valid"].address : t.header["valid"].end])
        if valid != 1:
            raise TableError(f"leg {self.leg}: the drive does not accept bank {bank} as valid after the write "
                             f"(its checksum check failed); the bank was not activated.")

    def activate_table(self, bank: int) -> None:
        """Make `bank` the active table (one register write). The drive checks the bank's
        checksum and refuses an invalid bank (TableError; the previous bank stays active)."""
        self._check_bank(bank)
        r = self.profile.registers["active_bank"]
        try:
            self._write(r.address, r.encode(bank))
        except RequestRefused as exc:
            why = {3: "its entries do not match its checksum (write it completely first)",
                   6: "the axis is moving (stop it first)"}.get(exc.exception_code, str(exc))
            raise TableError(f"leg {self.leg}: the drive refused to activate bank {bank}: {why}.") from None

    def set_table_enabled(self, on: bool) -> None:
        """Switch applying the active table on or off (one register write)."""
        if self.profile.table is None:
            raise self._no_table()
        r = self.profile.registers["table_enable"]
        self._write(r.address, r.encode(1 if on else 0))

    def close(self) -> None:
        """Release the bus (the connection closes when its last axis is closed). Idempotent."""
        if not self._closed:
            self._closed = True
            self.bus.release()


def table_spec(profile: DriveProfile) -> TableSpec | None:
    """What the drive of `profile` holds: its [table] section as a TableSpec; None for a drive
    without a table ([table] kind = "none")."""
    t = profile.table
    if t is None:
        return None
    return TableSpec(max_points=t.max_points, max_correction_um=t.max_correction_um,
                     entry_resolution_um=t.entry_scale_um, min_step_mm=TABLE_MIN_STEP_MM, banks=t.banks)


TABLE_MIN_STEP_MM = 0.001
"""The finest table step the station writes to a drive (1 um; the spacing register resolves 1 nm)."""


def table_registers(profile: DriveProfile, table: TableBank, where: str = "table") -> tuple[list[int], list[int], list[int]]:
    """(forward entry registers, reverse entry registers, header registers) for `table`.

    Entries are rounded to the profile's entry resolution. TableRefused naming `where` if the
    table does not fit the drive (`TableSpec.check`); TableError if `table.checksum` is given
    (non-zero) and differs from the CRC of the entries.
    """
    t = profile.table
    spec = table_spec(profile)
    if t is None or spec is None:
        raise TableError(f"{where}: the drive profile {profile.name} holds no compensation table: {profile.table_note}", hint="")
    n = len(table.error_fwd_um)
    spec.check(table, where, min_points=0)
    lo, hi = int_range(t.entry_type)
    fwd = [max(lo, min(hi, t.entry_counts(e))) & 0xFFFF for e in table.error_fwd_um]
    rev = [max(lo, min(hi, t.entry_counts(e))) & 0xFFFF for e in table.error_rev_um]
    crc = crc16_modbus(fwd + rev)
    if table.checksum and table.checksum != crc:
        raise TableError(f"{where}: the table's checksum 0x{table.checksum:04X} does not match its entries (0x{crc:04X}).", hint="")
    try:
        header = t.encode_header({"point_count": n, "start_position": table.start_mm, "spacing": table.spacing_mm,
                                  "units": t.units_code, "checksum": crc})
    except ValueError as exc:
        raise TableError(f"{where}: {exc}", hint="") from None
    return fwd, rev, header


def _writable_runs(profile: DriveProfile, header: list[int]) -> list[tuple[int, list[int]]]:
    """Contiguous runs (offset, words) of the writable header registers."""
    mask = [False] * len(header)
    for r in profile.table.header.values():
        if r.writable:
            for i in range(r.address, r.end):
                mask[i] = True
    runs, start = [], None
    for i, w in enumerate(mask + [False]):
        if w and start is None:
            start = i
        elif not w and start is not None:
            runs.append((start, header[start:i]))
            start = None
    return runs


def connect_axes(
    url: str,
    legs: Sequence[int],
    profile: DriveProfile | None = None,
    timeout_s: float = 1.0,
    retries: int = 1,
    clock: Clock | None = None,
    **axis_options,
) -> dict[int, ModbusServoAxis]:
    """Connect to the drives of `legs` on one bus (unit ids from the profile: by default the leg
    number) and check each answers with the profile's register map version (or, for a drive
    without one, at its statusword). CommTimeout naming the URL if one does not."""
    profile = profile or DriveProfile.load()
    bus = ModbusBus.from_url(url, timeout_s=timeout_s, retries=retries)
    axes: dict[int, ModbusServoAxis] = {}
    try:
        for leg in legs:
            axis = ModbusServoAxis(bus, leg, profile, clock=clock, **axis_options)
            axes[leg] = axis
            axis.check_map_version()
            axis.limits()
    except BaseException:
        for axis in axes.values():
            axis.close()
        bus.close()
        raise
    return axes
