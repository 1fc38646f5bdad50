"""The HDF5 session schema: one place for field names, types and units.

Layout of a session file (schema version SCHEMA_VERSION, attribute `schema_version` on the root):

    /                      attrs: schema_version, software_version, session_id, operator,
                                  started_utc, ended_utc, outcome, rig ("sim"/"live"/"replay"/"import")
    /points                compound dataset, one row per measured point (POINT_DTYPE), chunked,
                           resizable; attrs `units_<field>` give each field's unit
    /faults                compound dataset (FAULT_DTYPE), one row per fault event
    /meta                  group; attrs hold JSON strings: plan, station_config, devices, and
                           (1.1, optional) identity (procedures/io/recording/identity.py)

Sign convention: `error_um` = measured minus target (interferometer minus commanded target),
micrometres; positive = the leg is longer than commanded. `direction` +1 = approached while the
position increased.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import MISSING, dataclass, field, fields
from operator import attrgetter
from typing import Any

import numpy as np

SCHEMA_VERSION = "1.2"  # major.minor; readers refuse another major (1.1 added /meta identity, 1.2 the root stage)

_NAN = float("nan")


def _column(dtype: str, unit: str, default: Any = MISSING) -> Any:
    """A field of a record type that is a column of a session dataset: its numpy type in the
    file and its unit (the `units_<name>` attribute)."""
    return field(default=default, metadata={"dtype": dtype, "unit": unit})


@dataclass(frozen=True, slots=True)
class PointRecord(Mapping):
    """One measured point: a row of /points. The fields are the columns, in file order; the
    numpy type of the row (`POINT_DTYPE`) and the units are derived from them, so a field added
    here is a column of every writer and reader at once (at the end: schema 1.x readers read
    rows by name, and ADDED_POINT_FIELDS says which older files lack).

    `to_row()` is the row as a tuple in field order (numpy's `np.array([rec.to_row()],
    POINT_DTYPE)`, or the recorder's struct packing); `from_row` reads one back. A record also
    reads as a mapping of the field names (`rec["error_um"]`, `dict(rec)`) for the consumers
    keyed by column name (displays, an export).

    Unknown values are NaN ("not measured", never zero); `flags` 0 is no flag.
    """

    index: int = _column("<i8", "1")  # position of the point in the plan (for resume): unique per session
    leg: int = _column("<i2", "1")
    run: int = _column("<i4", "1")  # one-direction pass number within the leg, 1-based
    direction: int = _column("<i1", "1")  # +1 / -1
    target_mm: float = _column("<f8", "mm")
    commanded_mm: float = _column("<f8", "mm", _NAN)  # what was sent to the drive
    drive_position_mm: float = _column("<f8", "mm", _NAN)  # drive-reported position actual
    measured_mm: float = _column("<f8", "mm", _NAN)  # interferometer reading
    error_um: float = _column("<f8", "um", _NAN)  # measured - target
    time_s: float = _column("<f8", "s", _NAN)  # since the session start
    air_temp_c: float = _column("<f8", "degC", _NAN)
    air_pressure_hpa: float = _column("<f8", "hPa", _NAN)
    humidity_pct: float = _column("<f8", "%RH", _NAN)
    material_temp_c: float = _column("<f8", "degC", _NAN)
    load_n: float = _column("<f8", "N", _NAN)  # axial load, compression positive
    signal_pct: float = _column("<f4", "%", _NAN)
    flags: int = _column("<u4", "bitfield", 0)  # see FLAG_*
    # on-the-fly capture (docs/onthefly.md): signed speed of the axis when the reading was
    # latched, + = increasing position; NaN for stop-and-go readings (taken at rest after the
    # dwell) and in files written before the field existed
    speed_mm_s: float = _column("<f8", "mm/s", _NAN)

    def to_row(self) -> tuple:
        """The field values in file order (the order of POINT_DTYPE)."""
        return _POINT_ROW(self)

    @classmethod
    def from_row(cls, row: np.void | tuple) -> "PointRecord":
        """The record of one POINT_DTYPE row (a numpy record, or a tuple in field order), as
        Python numbers."""
        return cls(*(row.tolist() if isinstance(row, np.void) else row))

    # the mapping view: the field names, in file order
    def __getitem__(self, name: str) -> Any:
        if name not in POINT_UNITS:
            raise KeyError(name)
        return getattr(self, name)

    def __iter__(self) -> Iterator[str]:
        return iter(POINT_NAMES)

    def __len__(self) -> int:
        return len(POINT_NAMES)


POINT_FIELDS: list[tuple[str, str, str]] = [(f.name, f.metadata["dtype"], f.metadata["unit"]) for f in fields(PointRecord)]
"""(name, numpy type, unit) of each /points column, in file order: derived from PointRecord."""
POINT_NAMES = tuple(n for n, _, _ in POINT_FIELDS)
POINT_DTYPE = np.dtype([(n, t) for n, t, _ in POINT_FIELDS])
POINT_UNITS = {n: u for n, _, u in POINT_FIELDS}
_POINT_ROW = attrgetter(*POINT_NAMES)

# flags bits
FLAG_RETRIED_BEAM = 1  # the reading needed a retry after a beam break
FLAG_RETRIED_DRIVE = 2  # the move needed a retry after a drive fault/timeout
FLAG_IMPORTED = 4  # came from CSV: commanded/drive/measured positions are derived
FLAG_REPLAYED = 8  # came from a replay device
FLAG_ANCHOR = 16  # on the fly: the pass's anchor, read at rest where the pass ends (docs/onthefly.md)
FLAG_PROBE = 32  # on the fly: a reversal probe, a stop-and-go reading right after a reversal (docs/onthefly.md)
FLAG_FRAMES_LOST = 64  # a streaming laser (uLine-F1) lost frames in the reading's window (CRC, cut, gap): fewer samples
FLAG_REREFERENCED = 128  # the laser lost its count (velocity overflow): the leg was re-zeroed at its reference first

FAULT_FIELDS: list[tuple[str, str, str]] = [
    ("index", "<i8", "1"),  # plan index of the point the fault hit
    ("leg", "<i2", "1"),
    ("run", "<i4", "1"),
    ("target_mm", "<f8", "mm"),
    ("time_s", "<f8", "s"),
    ("kind", "S16", ""),  # a FaultKind value: beam_break / drive_fault / timeout / framing / error
    ("attempt", "<i2", "1"),
    ("gave_up", "<i1", "1"),  # 1 when retries were exhausted and the point was skipped/failed
    ("message", "S200", ""),
]
FAULT_DTYPE = np.dtype([(n, t) for n, t, _ in FAULT_FIELDS])

OPTIONAL_NAN_FIELDS = ("time_s", "air_temp_c", "air_pressure_hpa", "humidity_pct", "material_temp_c", "load_n")
"""Fields that may be unknown (NaN) in imported data: NaN means 'not measured', never zero."""

# --- additions (recording writer/reader) -------------------------------------------------------

FAULT_UNITS = {n: u for n, _, u in FAULT_FIELDS}

POINT_REQUIRED_KEYS = tuple(f.name for f in fields(PointRecord) if f.default is MISSING)
"""Keys a point record must carry (index, leg, run, direction, target_mm); every other POINT_DTYPE
field defaults to unknown (NaN, or 0 for `flags`)."""

ROOT_ATTRS = (
    "schema_version", "software_version", "session_id", "operator", "rig",
    "started_utc", "ended_utc", "outcome", "resumed_utc",
)
"""Root attributes of a session file, all strings. `ended_utc` and `outcome` are "" while the
session is open or when it was cut short; `resumed_utc` is a JSON list of the UTC times at which
the session was resumed ("[]" when never)."""

OPTIONAL_ROOT_ATTRS = ("stage",)
"""Root attributes added in 1.2: `stage`, the stage of the leg's life ("as_found", "as_left",
"other"; procedures/io/recording/stage.py). A file without it reads it derived."""

META_ATTRS = ("plan", "station_config", "devices")
"""Attributes of the /meta group: JSON text."""

OPTIONAL_META_ATTRS = ("identity",)
"""/meta attributes added in 1.1: a file without them (1.0, an import) reads them as unknown."""

# The root `outcome` attribute of a finished session holds an `Outcome.written()` value
# (procedures/vocabulary.py): "completed", "aborted" or "failed"; "" while open or when cut short.

POINTS_CHUNK_ROWS = 32  # 3.5 kB: each flush rewrites the whole last chunk, so keep it about a page
FAULTS_CHUNK_ROWS = 16
UNWRITTEN_INDEX = -1
"""Fill value of `index`: a row whose index is -1 was allocated but never written (a kill
between growing the dataset and writing the row). Readers drop such rows."""


ADDED_POINT_FIELDS = ("speed_mm_s",)
"""Point fields added after schema 1.0 (minor additions): a file without them is read with them
unknown (NaN), not refused."""


def schema_major(version: str) -> int:
    """The major number of a "major.minor" schema version string (ValueError if malformed)."""
    return int(str(version).split(".")[0])
