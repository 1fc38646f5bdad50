"""The platform experiment's inputs and report, for both front ends (`station platform`, the
terminal UI's F7 Platform page): the leg error sources from a session, a model or a table with
its recording (`load_errors`, `model_errors` for a model held in memory), and the report files
(`write_report`: Markdown + JSON summary and histograms).

Which error (docs/platform.md, docs/metrology.md): the recording's error on the basis of the
compensation, as `station fit` and `station report` use it: with a model, the basis the model
records (`options.error_basis`: normalised to 20 degC when the model is, raw for a model fitted
with --raw or one that does not say); with a table or the session alone, normalised to 20 degC
by default (a table from `station table` holds what the default model holds), raw with `raw`
(`--raw`). A normalised model with `raw` is refused. `inputs["error_basis"]` states it."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from procedures.io.atomic_outputs import atomic_folder, write_text_atomic
from procedures.vocabulary import InputError
from station.services.job import OfflineJob

if TYPE_CHECKING:  # annotations only: the experiment loads when it runs
    from procedures.platform.experiment import ExperimentResult
    from procedures.platform.geometry import Geometry
    from station.services.analysis import SessionAnalysis
    from station.services.config import StationConfig

REPORT_MD = "platform_report.md"
SUMMARY_JSON = "platform_summary.json"
POSITION_PNG = "pose_position_hist.png"
ORIENTATION_PNG = "pose_orientation_hist.png"
LEG_PNG = "leg_error_hist.png"


def _recording_for_model(src: Path, model, recording: str | Path | None) -> tuple[object, Path, bool]:
    """The session the model's measured errors come from, and whether it is another one than the
    model was fitted to (held out)."""
    from procedures.io.recording.reader import read_session

    source_path = model.source.get("path", "")
    source_sha = model.source.get("sha256", "")
    if recording:
        rec_path = Path(recording)
    elif source_path:
        rec_path = Path(source_path)
        if not rec_path.is_absolute() and not rec_path.exists():
            rec_path = src.parent / source_path  # recorded relative to the model's folder
    else:
        raise InputError(f"{src}: the model names no recording; pass --recording FILE.h5 for the measured errors.")
    if not rec_path.exists():
        raise InputError(f"{src}: its recording {rec_path} is not there; pass --recording FILE.h5 for the measured errors.")
    session = read_session(rec_path)
    held_out = bool(source_sha) and session.sha256 != source_sha
    if not recording and held_out:
        raise InputError(
            f"{rec_path} changed since {src} was fitted to it (sha256 {session.sha256[:12]}... vs "
            f"{source_sha[:12]}...); pass --recording {rec_path} to use it anyway."
        )
    return session, rec_path, held_out


def check_model_legs(model, name) -> None:
    """Refuse a model that does not cover all six legs (InputError naming `name`)."""
    missing = [leg for leg in range(1, 7) if leg not in model.legs]
    if missing:
        raise InputError(f"{name}: the model has no leg(s) {missing}; the platform needs all six legs modelled.")


def recording_error(session, *, model=None, raw: bool = False, model_name: str = "the model") -> tuple[object, dict]:
    """The recording's points with `error_um` on the compensation's basis (module docstring) and
    that basis as JSON ({"basis": "normalised"|"raw", "lines": [what the commands print], ...})."""
    from procedures.reporting.session_report import report_basis

    points, _, basis = report_basis(session.points, getattr(session, "station_config", None), model, raw,
                                    model_name=model_name)
    return points, basis


def _both_measurements(session, predicted_um, where: str, what: str, inputs: dict,
                       measured: str | None, *, model=None, raw: bool = False,
                       model_name: str = "the model") -> tuple[object, object, dict]:
    """Error sources for the main measurement (`measured`, default 'mean') and the other one,
    both from the recording's points (on the compensation's basis) with `predicted_um` as
    compensation."""
    from procedures.platform.experiment import RecordedLegErrors

    measured = measured or "mean"
    other = "pass" if measured == "mean" else "mean"
    points, inputs["error_basis"] = recording_error(session, model=model, raw=raw, model_name=model_name)

    def errors(measurement: str):
        return RecordedLegErrors(points, predicted_um=predicted_um, source=where, measurement=measurement,
                                 compensation=what)

    inputs["measured"] = measured
    return errors(measured), errors(other), inputs


def model_errors(model, session, recording_path, model_path, *, measured: str | None = None, held_out: bool = False,
                 model_label: str | None = None, raw: bool = False) -> tuple[object, object, dict]:
    """Error sources (main measurement, other measurement) and the report's inputs for a fitted
    model (procedures.fit) applied to a read session: what `station platform MODEL.json` runs,
    also for a model held in memory (the terminal UI's; `model_path` None when it is not saved,
    `model_label` then names it in the description)."""
    check_model_legs(model, model_path or model_label or "the model")
    inputs = {
        "model": {"path": None if model_path is None else str(model_path), "method": model.method, "source": model.source,
                  "integrity": getattr(model, "integrity", "")},  # "" for a model in memory (the UI's)
        "recording": {"path": str(recording_path), "sha256": session.sha256},
        "recording_is_the_models_own": not held_out,
    }
    where = f"{recording_path} with model {model_label or model_path} ({model.method})"
    return _both_measurements(session, model.predict_um, where, "the model's prediction", inputs, measured,
                              model=model, raw=raw, model_name=str(model_path or model_label or "the model"))


def _table_errors(src: Path, recording, profile, measured: str | None, raw: bool = False) -> tuple[object, object, dict]:
    from procedures.io.recording.reader import file_sha256, read_session
    from procedures.compensation.table import read_table_csv
    from station.services.wiring import drive_table_spec

    if not recording:
        raise InputError(f"{src}: a table does not name its recording; pass --recording FILE.h5 for the measured errors.")
    table = read_table_csv(src, drive_table_spec(profile), expected_legs=6)
    rec_path = Path(recording)
    if not rec_path.exists():
        raise FileNotFoundError(f"{rec_path}: no such file")
    session = read_session(rec_path)

    def predicted_um(leg, position_mm, direction):
        return table.legs[leg].correction_um(position_mm, direction)

    inputs = {
        "table": {"path": str(src), "sha256": file_sha256(src),
                  "step_mm": {str(leg): t.step_mm for leg, t in table.legs.items()},
                  "integrity": table.integrity},  # "unverified": a file without its record (docs/tables.md)
        "recording": {"path": str(rec_path), "sha256": session.sha256},
    }
    return _both_measurements(session, predicted_um, f"{rec_path} with table {src}",
                              "the table, interpolated as the drive does,", inputs, measured, raw=raw)


def load_errors(source, *, recording=None, measured: str | None = None,
                profile=None, raw: bool = False) -> tuple[object, object | None, dict]:
    """The experiment's error source for the main tables, the one for the other measurement
    (None with FILE.h5 alone) and a description of the inputs for the report, from a session
    file, a model file or a table (with `recording`), as `station platform` takes them; the
    recording's error on the basis the module docstring states (`raw`: --raw)."""
    from procedures.platform.experiment import RecordedLegErrors
    from procedures.io.recording.reader import read_session

    src = Path(source)
    if not src.exists():
        raise FileNotFoundError(f"{src}: no such file")
    suffix = src.suffix.lower()
    if suffix == ".json":
        from procedures.fit import load_model

        model = load_model(src)
        check_model_legs(model, src)
        from procedures.reporting.session_report import basis_is_raw

        basis_is_raw(model, raw, model_name=str(src))  # refuse a basis mismatch before reading the recording
        session, rec_path, held_out = _recording_for_model(src, model, recording)
        return model_errors(model, session, rec_path, src, measured=measured, held_out=held_out, raw=raw)
    if suffix == ".csv":
        return _table_errors(src, recording, profile, measured, raw)
    if recording:
        raise InputError("--recording goes with MODEL.json or TABLE.csv; with FILE.h5 the session itself gives the errors.")
    if measured == "mean":
        raise InputError("--measured mean needs MODEL.json or TABLE.csv as compensation; with FILE.h5 the table is the mean "
                         "of the other passes.")
    session = read_session(src)
    points, basis = recording_error(session, raw=raw)
    return RecordedLegErrors(points, source=str(src)), None, {"recording": {"path": str(src), "sha256": session.sha256},
                                                              "measured": "pass", "error_basis": basis}


def _hist_figure(orig: np.ndarray, comp: np.ndarray, labels: list[str], unit: str, title: str, path: Path, ylabel: str = "poses") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(labels), 2, figsize=(9, 2.4 * len(labels)), squeeze=False)
    for k, label in enumerate(labels):
        lo = float(min(np.min(orig[:, k]), np.min(comp[:, k])))
        hi = float(max(np.max(orig[:, k]), np.max(comp[:, k])))
        if not hi > lo:
            hi = lo + 1e-12
        bins = np.linspace(lo, hi, 41)  # same bins left and right, so the narrowing is visible
        for col, (data, name) in enumerate(((orig[:, k], "original"), (comp[:, k], "compensated"))):
            ax = axes[k, col]
            counts, _ = np.histogram(data, bins=bins)
            # one filled step artist instead of 40 bar patches: drawing stays fast
            ax.stairs(counts, bins, fill=True, color="tab:red" if col == 0 else "tab:blue")
            ax.set_title(f"{label}: {name} error", fontsize=9)
            ax.set_xlabel(f"error ({unit})", fontsize=8)
            ax.set_ylabel(ylabel, fontsize=8)
            ax.tick_params(labelsize=7)
    fig.suptitle(title, fontsize=10)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.22 / len(labels), top=1 - 0.25 / len(labels), hspace=0.75, wspace=0.22)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _write_figures(result, out: Path) -> list[Path]:
    from procedures.platform.sensitivity import ARCSEC_PER_RAD

    ok = result.valid
    e0, e1 = result.pose_error[ok], result.pose_error_compensated[ok]
    paths = [out / POSITION_PNG, out / ORIENTATION_PNG, out / LEG_PNG]
    _hist_figure(e0[:, :3], e1[:, :3], ["x", "y", "z"], "um", "End-effector position errors (cf. the paper's Fig. 9)", paths[0])
    _hist_figure(e0[:, 3:] * ARCSEC_PER_RAD, e1[:, 3:] * ARCSEC_PER_RAD, ["rx", "ry", "rz"], "arcsec (1 arcsec = 4.848e-6 rad)",
                 "End-effector orientation errors (cf. the paper's Fig. 10)", paths[1])
    legs = result.leg_error_um[ok].reshape(-1, 1)
    legs_c = result.leg_compensated_um[ok].reshape(-1, 1)
    _hist_figure(legs, legs_c, ["all legs"], "um", "Leg errors at the sampled positions (cf. the paper's Figs. 7-8)", paths[2],
                 ylabel="leg positions")
    return paths


def write_report(out: Path, result, summary: dict, inputs: dict, geometry) -> list[Path]:
    """Complete `summary` (from `run_measurements`) with the inputs, geometry, home sensitivity
    and conventions, and write platform_report.md, platform_summary.json and the histograms into
    `out` (created). Returns the paths written: report, summary, figures."""
    from procedures.platform.geometry import describe
    from procedures.platform.platform_markdown import report_markdown
    from procedures.platform.sensitivity import sensitivity_report

    home = sensitivity_report(geometry, geometry.home_pose_mm_rad)
    summary["inputs"] = inputs
    summary["geometry"] = {
        "name": geometry.name,
        "source": geometry.source,
        "description": describe(geometry),
        "home_pose_mm_rad": [float(v) for v in geometry.home_pose_mm_rad],
    }
    summary["sensitivity_home"] = home
    summary["conventions"] = {
        "pose": "x_mm, y_mm, z_mm of the platform origin in the base frame; rx, ry, rz roll-pitch-yaw about fixed X, Y, Z, R = Rz Ry Rx",
        "pose_error": "FK pose from erroneous lengths minus the nominal pose; x, y, z in um, angles in rad (and arcsec)",
        "leg_error": "measured minus commanded, um; compensated = measured - predicted",
        "direction": "poses visited in the order drawn from home; a leg's direction is the sign of its last motion",
    }
    out = Path(out)
    with atomic_folder(out) as work:  # put into place when complete: Ctrl-C leaves no half folder
        write_text_atomic(work / REPORT_MD, report_markdown(summary, describe(geometry), home))
        write_text_atomic(work / SUMMARY_JSON, json.dumps(summary, indent=2, allow_nan=False) + "\n")
        figures = _write_figures(result, work)
    return [out / REPORT_MD, out / SUMMARY_JSON, *(out / f.name for f in figures)]


# -- the platform job (issue 32 part 1, one shape for every job) ----------------------------------

UNSAVED_MODEL = "fitted in the station UI, not saved (Results, F3: w saves it)"
COMPONENTS = ("x_um", "y_um", "z_um", "rx_rad", "ry_rad", "rz_rad")  # the pose error's components, in its order


@dataclass
class PlatformRequest:
    """What to run: `poses` random poses from `seed`, the leg errors of `source` (FILE.h5,
    MODEL.json or TABLE.csv with `recording`) or, with no source, of `analysis` (the UI's Results
    analysis: its model and session, or the held-out `recording`). `measured`, `profile`, `raw`
    as `station platform` takes them; `geometry`: a TOML (None: the paper-like positioner); the
    workspace half-ranges about home in mm and degrees; `out`: the report folder (None: written
    later, `write_platform_report`), replaced only with `force`."""

    poses: int = 2000
    seed: int = 0
    source: Path | None = None
    analysis: SessionAnalysis | None = None
    recording: Path | None = None
    measured: str | None = None
    profile: Path | None = None
    raw: bool = False
    geometry: Path | None = None
    xy_mm: float = 60.0
    z_mm: float = 60.0
    tilt_deg: float = 3.0
    yaw_deg: float = 0.0
    out: Path | None = None
    force: bool = False


@dataclass
class PlatformRun:
    """One finished experiment: the main measurement's result and summary (with the other
    measurement's digest), what went in, and where its report goes; the figures a front end
    shows, in its units (`pose_rows`, `dominant`, `histogram`)."""

    result: ExperimentResult
    summary: dict
    inputs: dict
    geometry: Geometry
    recording: Path
    label: str  # what was compensated with what, for the status line (file names only)
    analysis: SessionAnalysis | None = None
    written: list[Path] = field(default_factory=list)

    def measurement_label(self, measured: str | None, default: str = "the source") -> str:
        from procedures.platform.experiment import MEASUREMENT_LABELS

        return MEASUREMENT_LABELS.get(measured or "", default)

    def pose_rows(self) -> list[tuple[str, list[str]]]:
        """The paper's Table 2: (measure, cells per component)."""
        from procedures.platform.platform_markdown import pose_table_rows

        return list(pose_table_rows(self.summary))

    def dominant(self, stage: str, k: int) -> str:
        """The leg dominating component `k` "original" or "compensated", in words."""
        from procedures.platform.platform_markdown import dominant_text

        return dominant_text(self.summary["dominant_leg"][stage][k])

    def histogram(self, component: str, bins: int = 40) -> tuple[list[float], list[float], list[float], str]:
        """Step outlines of the original and compensated error of `component` on the same bins,
        positions in um, angles in arcsec: (x, counts original, counts compensated, unit)."""
        from procedures.platform.sensitivity import ARCSEC_PER_RAD

        k = COMPONENTS.index(component)
        ok = self.result.valid
        scale = 1.0 if k < 3 else ARCSEC_PER_RAD
        xs, c0, c1 = histogram_steps(self.result.pose_error[ok, k] * scale,
                                     self.result.pose_error_compensated[ok, k] * scale, bins)
        return xs, c0, c1, ("µm" if k < 3 else "arcsec")


def histogram_steps(orig: np.ndarray, comp: np.ndarray, bins: int = 40) -> tuple[list[float], list[float], list[float]]:
    """Step outlines of the histograms of `orig` and `comp` on the same bins (as the report's
    figures: the narrowing is visible): (x, counts original, counts compensated)."""
    lo = float(min(np.min(orig), np.min(comp)))
    hi = float(max(np.max(orig), np.max(comp)))
    if not hi > lo:
        hi = lo + 1e-12
    edges = np.linspace(lo, hi, bins + 1)
    c0, _ = np.histogram(orig, bins=edges)
    c1, _ = np.histogram(comp, bins=edges)
    xs = np.repeat(edges, 2)[1:-1]  # each bin's left and right edge
    return [float(x) for x in xs], [float(c) for c in np.repeat(c0, 2)], [float(c) for c in np.repeat(c1, 2)]


def require_six_legs(session, name: str) -> None:
    legs = [int(leg) for leg in session.legs]
    missing = [leg for leg in range(1, 7) if leg not in legs]
    if missing:
        raise InputError(
            f"{name} has leg(s) {legs}, no {missing}; the platform needs the errors of all six legs. "
            "Record a sweep of legs 1-6 (Sweep, F2) and fit it on Results (F3)."
        )


@dataclass
class PreparedPlatform(OfflineJob):
    request: PlatformRequest
    out: Path | None

    def run(self, sinks=(), control=None):
        """Load the error sources, run both measurements on the same poses and, with `out`, write
        the report. `data`: the PlatformRun; `lines`: what `station platform` prints after it."""
        import math

        from procedures.platform.experiment import Workspace, run_measurements
        from procedures.platform.geometry import default_geometry, load_geometry
        from station.services.job import JobOutcome

        r = self.request
        geometry = load_geometry(r.geometry) if r.geometry else default_geometry()
        a = r.analysis
        if r.source is None:  # the model on Results
            from procedures.io.recording.reader import read_session

            if r.recording is None:
                session, rec_path, held_out = a.session, a.path, False
            else:
                session, rec_path = read_session(r.recording), Path(r.recording)
                held_out = session.sha256 != a.session.sha256
            require_six_legs(session, rec_path.name)
            errors, other, inputs = model_errors(
                a.model, session, rec_path, a.model_path, held_out=held_out,
                model_label=None if a.model_path else f"fitted on {a.path.name} in the station UI, not saved")
            if a.model_path is None:
                inputs["model"]["note"] = UNSAVED_MODEL
            label = f"{a.method} model fitted on {a.path.name}" + (f", measured on {rec_path.name}" if held_out else "")
        else:
            source = Path(r.source)
            errors, other, inputs = load_errors(source, recording=r.recording, measured=r.measured,
                                                profile=r.profile, raw=r.raw)
            rec_path = Path(inputs["recording"]["path"])
            kind = "table" if source.suffix.lower() == ".csv" else "model"
            label = f"{kind} {source.name} on {rec_path.name}"
            a = None
        workspace = Workspace(r.xy_mm, r.z_mm, math.radians(r.tilt_deg), math.radians(r.yaw_deg))
        # same seed for the other measurement, so the same poses and directions: only the measurement differs
        result, summary = run_measurements(geometry, errors, other, poses=r.poses, seed=r.seed, workspace=workspace)
        if r.source is not None:
            summary["measured"] = inputs["measured"]
        run = PlatformRun(result, summary, inputs, geometry, rec_path, label, analysis=a)
        if self.out is None:
            return JobOutcome("done", data=run)
        run.written = write_report(self.out, result, summary, inputs, geometry)
        return JobOutcome("done", outputs=list(run.written), lines=platform_lines(run), data=run)


def prepare_platform(request: PlatformRequest, cfg: StationConfig | None = None) -> PreparedPlatform:
    """Every refusal before a pose is computed: the size (memory) of the run, the workspace's
    half-ranges, an output folder that exists. `lines`: the size estimate."""
    import math

    from station.services.sizing import check_platform_poses

    r = request
    size = check_platform_poses(r.poses)  # sized first: refused before anything is read or allocated
    for name in ("xy_mm", "z_mm", "tilt_deg", "yaw_deg"):
        value = getattr(r, name)
        if not (math.isfinite(value) and value >= 0):
            raise InputError(f"--{name.replace('_', '-')} must be a number >= 0, got {value}.")
    out = None
    if r.out is not None:
        from procedures.io.outputs import check_output_folder

        out = check_output_folder(r.out, force=r.force)  # before the poses are computed
    return PreparedPlatform(r, out, lines=[f"platform: {size.describe()}"])


def write_platform_report(run: PlatformRun, out: Path) -> list[Path]:
    """The CLI's report files for a run of the UI in `out` (any thread); a model saved on Results
    since the run is named by its file."""
    import copy

    inputs = copy.deepcopy(run.inputs)
    a = run.analysis
    if a is not None and a.model_path is not None and inputs.get("model", {}).get("path") is None:
        inputs["model"]["path"] = str(a.model_path)  # saved on Results since the run
        inputs["model"].pop("note", None)
    return write_report(out, run.result, dict(run.summary), inputs, run.geometry)


def platform_lines(run: PlatformRun) -> list[str]:
    """What `station platform` prints of a run: files read without their integrity record, the
    error basis, the measurement, Table 2, the reductions, the poses used and the files written."""
    from procedures.platform.platform_markdown import pose_table_markdown, reduction_lines

    inputs, summary = run.inputs, run.summary
    lines = []
    for kind in ("table", "model"):  # a file without its integrity record: read whole, said once (docs/tables.md)
        if (inputs.get(kind) or {}).get("integrity") == "unverified":
            from procedures.io.integrity import unverified_line

            lines.append(unverified_line(inputs[kind]["path"], kind, "every row and field checked"))
    lines += list(inputs["error_basis"]["lines"])
    lines += [f"measured leg error: {run.measurement_label(summary['measured'])}\n", pose_table_markdown(summary), "",
              reduction_lines(summary), f"poses used: {summary['poses_used']} of {summary['poses']}"]
    lines += [f"wrote {path}" for path in run.written]
    return lines
