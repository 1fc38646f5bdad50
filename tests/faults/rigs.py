"""The simulated rig behind a faulty link, and the truth of its drives read from their memory.

`faulty_rig()` starts a `SimRig`, puts a `ModbusFaultProxy` in front of its drive server and a
`SerialLineFaults` in front of its interferometer pty, and connects the station's ordinary
clients (drivers.modbus.client, drivers.interferometer.client) through them: a `station.services.wiring.Rig`
that the real jobs (station.services.jobs.run_sweep, station.services.table_jobs) use unchanged. Faults start
switched off (`rig.link.arm()` switches them on), so connecting is not what is tested.

`drive_truth(sim, leg)` reads a drive's active bank and table straight out of the simulated
drive's memory, not through the link: what is really active, to compare with what a push said.
Used by tests/faults/ and bench/bench_soak.py.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from drivers.interfaces import TableBank
from drivers.interferometer.client import SerialInterferometer
from drivers.modbus.client import connect_axes
from drivers.modbus.codec import crc16_modbus
from drivers.sim.faults import LINE_KINDS, TCP_KINDS, FaultSchedule, ModbusFaultProxy, SerialLineFaults
from drivers.sim.rig import SimRig
from procedures.compensation.push import table_sha256
from station.services.wiring import Rig

DRIVE_TIMEOUT_S = 0.4
"""The drive client's timeout on the faulty link (two attempts of 0.2 s): short, so a thousand
dropped frames cost minutes, not hours; long enough for a loaded two-core machine."""
LASER_TIMEOUT_S = 0.3


@dataclass
class Link:
    """The two faulty links of a rig and their schedules."""

    proxy: ModbusFaultProxy
    line: SerialLineFaults

    def arm(self, on: bool = True) -> None:
        self.proxy.schedule.enabled = on
        self.line.schedule.enabled = on

    @property
    def counts(self) -> Counter[str]:
        total: Counter[str] = Counter()
        total.update(self.proxy.counts)
        total.update(self.line.counts)
        return total


def faulty_rig(*, seed: int = 0, rate: float = 0.0, line_rate: float | None = None, every_s: float | None = None,
               tcp_kinds=TCP_KINDS, line_kinds=LINE_KINDS, legs=(1, 2, 3, 4, 5, 6), nv_path: Path | None = None,
               drive_timeout_s: float = DRIVE_TIMEOUT_S, laser_timeout_s: float = LASER_TIMEOUT_S,
               delay_s: tuple[float, float] = (0.01, 0.35)) -> tuple[Rig, Link]:
    """A simulated rig (time scale 0, plant seed `seed`) reached through faulty links. `rate`:
    fault probability per Modbus frame (`line_rate` per reply line, default the same), or
    `every_s`: a fault on each link every that many seconds of rig time on average. Close the
    returned Rig to stop everything."""
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    sim = SimRig(time_scale=0.0, seed=seed, nv_path=nv_path).start()
    closers = [sim.stop]
    try:
        clock = sim.clock if every_s else None
        tcp = FaultSchedule(tcp_kinds, seed=seed * 2 + 1, rate=0.0 if every_s else rate, every_s=every_s, clock=clock)
        lin = FaultSchedule(line_kinds, seed=seed * 2 + 2, rate=0.0 if every_s else (rate if line_rate is None else line_rate),
                            every_s=every_s, clock=clock)
        tcp.enabled = lin.enabled = False
        proxy = ModbusFaultProxy(sim.drive_url, tcp, delay_s=delay_s)
        proxy.start()
        closers.append(proxy.stop)
        line = SerialLineFaults(sim.laser_port, lin)
        line.start()
        closers.append(line.stop)
        axes = connect_axes(proxy.url, legs, sim.profile, timeout_s=drive_timeout_s, clock=sim.clock)
        laser = SerialInterferometer(line.path, timeout_s=laser_timeout_s)
    except BaseException:
        for c in reversed(closers):
            c()
        raise
    desc = f"simulated rig behind a faulty link: drives {proxy.url} -> {sim.drive_url}, interferometer {line.path}"
    return Rig(axes, laser, sim.clock, "sim", desc, sim.profile, sim, closers), Link(proxy, line)


@dataclass(frozen=True)
class DriveTruth:
    """A drive's table state as its memory holds it: `active_bank`, `table_enable`, and the
    active bank's table (None when the bank's checksum does not match: the drive applies nothing)."""

    active_bank: int
    table_enable: int
    table: TableBank | None

    @property
    def sha256(self) -> str | None:
        return None if self.table is None else table_sha256(self.table)


def drive_truth(sim: SimRig, leg: int) -> DriveTruth:
    """Read leg `leg`'s table state from the simulated drive's memory (under the rig lock), not
    through any link."""
    server = sim.drive_server
    t = server.profile.table
    with server.lock:
        state = server._models[leg].nv_state()  # noqa: SLF001 - the truth, read beside the protocol
    bank = int(state["active_bank"])
    words = state["banks"][bank]
    h = t.decode_header(words[: t.header_words])
    n = int(h["point_count"])
    base = t.bank_base[bank]
    fwd = words[t.fwd_address(bank) - base: t.fwd_address(bank) - base + n]
    rev = words[t.rev_address(bank) - base: t.rev_address(bank) - base + n]
    if n > t.max_points or crc16_modbus(fwd + rev) != h["checksum"]:
        return DriveTruth(bank, int(state["table_enable"]), None)
    to_um = lambda ws: tuple((w - 0x10000 if w & 0x8000 else w) * t.entry_scale_um for w in ws)  # noqa: E731
    return DriveTruth(bank, int(state["table_enable"]),
                      TableBank(h["start_position"], h["spacing"], to_um(fwd), to_um(rev), h["checksum"]))
