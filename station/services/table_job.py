"""The table job (issue 32 part 1, one shape for every job): `station table` fills a
`TableRequest`; `prepare_table` loads the model, checks the legs and every output, finds the
limits of the format (the drive profile's, LinuxCNC's, a controller's, or the station's own table
store) and makes the checked table (station.services.table_jobs.make_checked_table); a table the
plausibility checks refused becomes the job's `question` ("make it anyway?") with the refusal
kept in `refusal`. `PreparedTable.run` writes the file(s) and says what they hold."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from procedures.compensation import controllers
from procedures.vocabulary import InputError
from station.services.job import JobOutcome, OfflineJob

if TYPE_CHECKING:  # annotations only
    from drivers.interfaces import TableSpec
    from procedures.compensation.table import CompTable
    from procedures.fit.model import LegErrorModel
    from station.services.config import StationConfig

TABLE_FORMATS: tuple[str, ...] = ("csv", "linuxcnc", *controllers.FORMATS)
"""What a table can be written as: the drive's CSV, LinuxCNC COMP_FILEs, or a controller's files."""


@dataclass
class TableRequest:
    """Make a table of the model file `model` into `out` (a CSV; for linuxcnc a folder or
    NAME.comp; replaced only with `force`) in `format` (TABLE_FORMATS) on `step_mm` (None: the
    recording's spacing, coarsened to the point limit). `profile`: the drive profile whose
    limits apply (None: built in); `legs`: leg text ("1-3"; None: all in the model); `config`:
    the station TOML whose catalog indexes a CSV; the rest are the formats' options."""

    model: Path
    out: Path
    format: str = "csv"
    step_mm: float | None = None
    profile: Path | None = None
    legs: str | None = None
    config: Path | None = None
    force: bool = False
    accept_implausible: bool = False
    comp_type: int = 0
    siemens_mode: str = "cec"
    reference_mm: float = 0.0
    axis_name: str = "X"
    ecmc_direction: str = "mean"


def output_paths(fmt: str, out: str | Path, legs) -> list[Path]:
    """The files format `fmt` to `out` writes for `legs`, known before the table is made."""
    from procedures.compensation.controllers.linuxcnc import linuxcnc_paths

    if fmt == "csv":
        return [Path(out)]
    if fmt == "linuxcnc":
        return list(linuxcnc_paths(out, legs).values())
    from procedures.compensation.controllers.common import leg_paths

    module = controllers.module(fmt)
    return list(leg_paths(out, legs, module.SUFFIX, stem=getattr(module, "STEM", "leg{leg}")).values())


def _soft_limits(profile) -> tuple[float, float] | None:
    """The soft limits of the drive profile (default the built-in one), when it states them."""
    from station.services.wiring import drive_soft_limits

    try:
        return drive_soft_limits(profile)
    except Exception:  # noqa: BLE001 (a bad profile is refused by drive_table_spec with its own message)
        return None


@dataclass
class PreparedTable(OfflineJob):
    """A table made and checked. `refusal`: the plausibility checks' ImplausibleError when they
    refused it (then `question` asks whether to make it anyway; `run` after a yes makes it with the
    checks' findings as warnings)."""

    request: TableRequest
    model: LegErrorModel
    legs: list[int] | None
    limits: TableSpec
    soft_limits_mm: tuple[float, float] | None
    table: CompTable | None = None  # None while refused
    warnings: list[str] = field(default_factory=list)
    refusal: Exception | None = None

    def run(self, sinks=(), control=None) -> JobOutcome:
        import numpy as np

        from station.services.table_jobs import make_checked_table, write_table

        r, model, limits = self.request, self.model, self.limits
        if self.table is None:  # refused by the checks and confirmed: made anyway
            self.table, self.warnings = make_checked_table(model, r.step_mm, limits, legs=self.legs,
                                                           accept_implausible=True, soft_limits_mm=self.soft_limits_mm)
        table = self.table
        if r.format == "csv":
            from station.services.config import load_config

            written = [write_table(table, r.out, load_config(r.config), limits)]
        elif r.format in controllers.FORMATS:
            options = {"siemens840d": {"mode": r.siemens_mode, "reference_mm": r.reference_mm},
                       "heidenhain": {"axis": r.axis_name}, "ecmc": {"direction": r.ecmc_direction}}
            written = controllers.module(r.format).write(table, r.out, spec=limits, **options.get(r.format, {}))
        else:
            from procedures.compensation.controllers.linuxcnc import write_linuxcnc_comp

            written = write_linuxcnc_comp(table, r.out, r.comp_type, limits)
        lines = [f"model: {r.model} ({model.method}; from {model.source.get('path') or 'unknown recording'})"]
        lines += self.warnings
        basis = model.options.get("error_basis")
        if isinstance(basis, dict):  # what `station fit` fitted (docs/metrology.md)
            ref = basis.get("reference_temp_c", 20.0)
            lines.append("error: normalised to " + f"{ref:g} degC material temperature (the table holds the leg's "
                         f"error at {ref:g} degC)" if basis.get("normalised") else "error: RAW, not normalised to "
                         "20 degC (the table holds the error at the calibration's temperatures)")
        else:
            lines.append("error: not stated by the model (fitted before normalisation to 20 degC existed: raw)")
        for leg, t in table.legs.items():
            worst = max(float(np.max(np.abs(t.error_fwd_um))), float(np.max(np.abs(t.error_rev_um))))
            lines.append(f"leg {leg}: {t.point_count} points, {t.start_mm:g} .. {t.end_mm:g} mm step {t.step_mm:g} mm, "
                         f"largest correction {worst:.3f} um (limit {limits.max_correction_um:g} um)")
        lines += [f"wrote {path}" for path in written]
        if r.format == "linuxcnc":
            lines.append(f"LinuxCNC: [JOINT_n] COMP_FILE = <file>  COMP_FILE_TYPE = {r.comp_type}  (machine units mm)")
        elif r.format in controllers.FORMATS:
            lines.append(controllers.HINTS[r.format])
        else:
            lines.append(f"next: station push {written[0]} --leg N --sim")
        return JobOutcome("done", outputs=[Path(p) for p in written], lines=lines, data=table)


def prepare_table(request: TableRequest, cfg: StationConfig | None = None) -> PreparedTable:
    """Every refusal before a file is written (InputError): a model without the legs asked for, an
    output that exists, a profile whose table limits cannot be had, corrections beyond the soft
    limits; and the plausibility checks (their refusal kept, as the job's question)."""
    from procedures.acquisition.plans import parse_legs
    from procedures.fit import load_model
    from procedures.fit.model_io import unverified_model_line
    from procedures.io.outputs import check_output_file
    from procedures.metrology.plausibility import ImplausibleError
    from station.services.table_jobs import make_checked_table
    from station.services.wiring import drive_table_spec

    r = request
    lines: list[str] = []
    model = load_model(r.model)
    unverified = unverified_model_line(r.model, model)
    if unverified:
        lines.append(unverified)
    legs = parse_legs(r.legs) if r.legs else None
    if legs is not None:
        missing = [x for x in legs if x not in model.legs]
        if missing:
            raise InputError(f"{r.model}: the model has no leg(s) {missing} (it has {list(model.legs)})")
    for path in output_paths(r.format, r.out, legs or list(model.legs)):  # before anything is made
        check_output_file(path, force=r.force, make_parents=r.format != "csv")
    if r.format in controllers.FORMATS:
        limits = controllers.module(r.format).LIMITS
    elif r.format == "linuxcnc":
        from procedures.compensation.controllers.linuxcnc import LINUXCNC_LIMITS

        drive = drive_table_spec(r.profile) if r.profile else None
        limits = LINUXCNC_LIMITS if drive is None else replace(
            LINUXCNC_LIMITS, max_points=min(drive.max_points, LINUXCNC_LIMITS.max_points),
            max_correction_um=drive.max_correction_um)
    else:
        limits = drive_table_spec(r.profile)
        if limits is None:  # a drive without a table: the CSV is for the station's own table (target station)
            from station.services.wiring import station_store_table_spec

            limits = station_store_table_spec("[compensation] tables_path")
            lines.append(f"note: the drive of {r.profile} holds no compensation table; the table is checked for the "
                         "station's table store (compensation target station, docs/compensation.md); for the "
                         "controller use --format linuxcnc")
    # the unit-slip and held-out checks are the service's, as on the UI's Compensation page; a drive table ends
    # within the drive's soft limits (the profile's), where the push will check it
    soft = _soft_limits(r.profile) if r.format == "csv" else None
    job = PreparedTable(r, model, legs, limits, soft, lines=lines)
    try:
        job.table, job.warnings = make_checked_table(model, r.step_mm, limits, legs=legs,
                                                     accept_implausible=r.accept_implausible, soft_limits_mm=soft)
    except ImplausibleError as exc:
        job.refusal, job.question = exc, "Make the table anyway?"
    return job
