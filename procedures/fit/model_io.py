"""Model files: JSON naming the recording they came from.

    {"format": "station-leg-error-model", "version": 1, "method": "default"|"paper",
     "source": {"path": ..., "sha256": ...}, "created_utc": ..., "options": {...},
     "identity": {"station": {"id", "host"}, "operator", "software_version",
                  "legs": {"1": {"serial", "part_number", "leg_type"}}},   (optional: older files lack it)
     "legs": {"1": {"stroke_mm": [min, max], "target_spacing_mm": ..., "stats": {...},
                    "model": {... method specific ...}}, ...}}

The file carries its integrity record, `"integrity": {"legs": N, "sha256": ...}`: the hash of
the document without it, as written (procedures/io/integrity.py). `load_model` refuses a file whose
record does not match (edited; a cut JSON file is not JSON) naming what differs, and reads a file
without one (hand-made, or older) as `integrity` "unverified" (the CLI says so in one line).

The content is deterministic: the same points and options give the same file apart from
`source` and `created_utc` (keys sorted, floats written with Python's round-trip repr).
A file that is not JSON, is another format, or lacks or mistypes a field is refused with a
`SchemaError` naming the file and the field; so is a value no fit of a real leg gives
(`procedures.io.ranges.SESSION_BOUNDS`: a stroke a metre from mid-stroke, an error of 0.1 m, a
leg other than 1-6, a basis or sample grid too large to evaluate).
"""

from __future__ import annotations

import json
import math
import os
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from procedures.io.atomic_outputs import write_text_atomic
from procedures.vocabulary import SchemaError
from procedures.fit.bidirectional import bidirectional_from_json
from procedures.fit.model import FORMAT, METHODS, VERSION, FitStats, LegErrorModel, LegFit
from procedures.fit.paper import paper_from_json
from procedures.io.integrity import IntegrityError, check_json_record, json_record, unverified_line, wrong_kind
from procedures.io.ranges import LEG_NUMBERS, SESSION_BOUNDS

MAX_SAMPLES = 100_000  # paper model: samples of the stroke (the paper's sweep has 361)
MAX_WAVES = 100  # default model: stroke harmonics (the fit tries at most 24)
MAX_LEAD_HARMONICS = 10  # default model (the fit tries at most 3)


def _clean(value: Any) -> Any:
    """JSON-safe: NaN/inf never reach a file (they are not JSON); numpy scalars become Python."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def model_to_json(model: LegErrorModel, source_path: str | os.PathLike | None = None,
                  source_sha256: str | None = None, created_utc: str | None = None,
                  identity: dict | None = None) -> str:
    """The model file's text (see the module docstring); `identity` defaults to the model's."""
    doc = {
        "format": FORMAT,
        "version": VERSION,
        "method": model.method,
        "source": {
            "path": str(source_path) if source_path is not None else model.source.get("path", ""),
            "sha256": source_sha256 if source_sha256 is not None else model.source.get("sha256", ""),
        },
        "created_utc": created_utc if created_utc is not None else datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "options": model.options,
        "legs": {str(leg): f.to_json() for leg, f in model.legs.items()},
    }
    identity = identity if identity is not None else model.identity
    if identity:
        doc["identity"] = identity
    doc = _clean(doc)
    doc[INTEGRITY_KEY] = json_record(doc, "legs", len(doc["legs"]))  # the hash of all of the above
    return json.dumps(doc, indent=2, sort_keys=True, allow_nan=False) + "\n"


INTEGRITY_KEY = "integrity"
REMAKE = "fit the recording again (`station fit SESSION.h5 --out MODEL.json`) or restore the file from where it came"
_NOT_A_MODEL = "give the model JSON `station fit` wrote (station fit SESSION.h5 --out MODEL.json)"


def unverified_model_line(path: str | os.PathLike, model: LegErrorModel) -> str | None:
    """The one warning line for a model file read without an integrity record, else None."""
    if model.integrity != "unverified":
        return None
    return unverified_line(path, "model", f"legs {', '.join(map(str, model.legs))}, every field checked")


def save_model(model: LegErrorModel, path: str | os.PathLike, source_path: str | os.PathLike | None = None,
               source_sha256: str | None = None, identity: dict | None = None) -> Path:
    """Write `model` as JSON to `path` (atomically: a partial file never replaces a good one);
    `identity`: the session's (procedures.io.recording.identity.model_identity), default the model's."""
    path = Path(path)
    text = model_to_json(model, source_path, source_sha256, identity=identity)
    return write_text_atomic(path, text)


# -- reading ---------------------------------------------------------------------------------

def _finite(x: int | float) -> bool:
    """math.isfinite, False for an integer beyond any float (JSON integers are unbounded)."""
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


class _Checker:
    def __init__(self, path: Path):
        self.path = path

    def fail(self, where: str, problem: str) -> SchemaError:
        return SchemaError(f"{self.path}: {where}: {problem}; this is not a model file written by `station fit` "
                           "(or it was edited or truncated): fit the recording again")

    def get(self, d: Any, key: str, where: str) -> Any:
        if not isinstance(d, dict):
            raise self.fail(where, "expected an object")
        if key not in d:
            raise self.fail(f"{where}.{key}" if where else key, "missing")
        return d[key]

    def number(self, d: Any, key: str, where: str, *, optional: bool = False, integer: bool = False) -> Any:
        v = self.get(d, key, where)
        name = f"{where}.{key}" if where else key
        if v is None and optional:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (integer and not isinstance(v, int)):
            raise self.fail(name, f"expected {'an integer' if integer else 'a number'}, got {v!r:.40}")
        if not _finite(v):
            raise self.fail(name, "not a finite number")
        return v

    def numbers(self, d: Any, key: str, where: str, *, length: int | None = None, integer: bool = False) -> list:
        v = self.get(d, key, where)
        name = f"{where}.{key}"
        if not isinstance(v, list):
            raise self.fail(name, "expected a list of numbers")
        for i, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, (int, float)) or (integer and not isinstance(x, int)) or not _finite(x):
                raise self.fail(f"{name}[{i}]", f"expected a finite {'integer' if integer else 'number'}, got {x!r:.40}")
        if length is not None and len(v) != length:
            raise self.fail(name, f"expected {length} values, got {len(v)}")
        return v

    def within(self, value: float, name: str, lo: float, hi: float, unit: str = "") -> float:
        """`value` when lo <= value <= hi, else a SchemaError naming the field and the range."""
        if not lo <= value <= hi:
            u = f" {unit}" if unit else ""
            raise self.fail(name, f"{value:.6g}{u} is outside {lo:.6g} .. {hi:.6g}{u}, which no fit of a real leg gives")
        return value

    def errors_um(self, values: list[float], name: str, indexed: bool = True) -> None:
        """Each of `values` (um) within +/- the session bound of an error."""
        bound = SESSION_BOUNDS.max_error_um
        for i, v in enumerate(values):
            if abs(v) > bound:
                where = f"{name}[{i}]" if indexed else name
                raise self.fail(where, f"{v:.6g} um is beyond +/-{bound:.6g} um, which no fit of a real leg gives")


_STAT_INT = ("n_points", "n_passes", "n_cycles", "dropped", "folds")
_STAT_OPT = ("noise_floor_um", "within_pass_um", "heldout_rms_um", "heldout_range_um")
_STAT_OLD = {"heldout_range_um": "range_after_um"}  # the name in files written before docs/figures.md


def _stats(c: _Checker, d: Any, where: str) -> FitStats:
    kw: dict[str, Any] = {k: c.number(d, k, where, integer=True) for k in _STAT_INT}
    for k in _STAT_OPT:
        old = _STAT_OLD.get(k)
        if old is not None and isinstance(d, dict) and k not in d and old in d:
            kw[k] = c.number(d, old, where, optional=True)
        else:
            kw[k] = c.number(d, k, where, optional=True)
    kw["range_before_um"] = c.number(d, "range_before_um", where)
    for k, v in kw.items():
        if v is not None:
            if k in _STAT_INT:
                c.within(v, f"{where}.{k}", 0, 2**31 - 1)
            else:
                c.within(v, f"{where}.{k}", 0, SESSION_BOUNDS.max_error_um, "um")
    note = d.get("note", "")
    kw["note"] = note if isinstance(note, str) else ""
    return FitStats(**kw)


def _leg(c: _Checker, method: str, leg: int, d: Any) -> LegFit:
    where = f"legs.{leg}"
    lo, hi = SESSION_BOUNDS.stroke_mm
    stroke = c.numbers(d, "stroke_mm", where, length=2)
    if not stroke[0] < stroke[1]:
        raise c.fail(f"{where}.stroke_mm", f"minimum {stroke[0]} is not below maximum {stroke[1]}")
    for i, x in enumerate(stroke):
        c.within(x, f"{where}.stroke_mm[{i}]", lo, hi, "mm")
    spacing = c.number(d, "target_spacing_mm", where)
    if not 0 < spacing <= stroke[1] - stroke[0]:
        raise c.fail(f"{where}.target_spacing_mm", f"{spacing:.6g} mm is not a step within the stroke")
    stats = _stats(c, c.get(d, "stats", where), f"{where}.stats")
    m = c.get(d, "model", where)
    mw = f"{where}.model"
    if method == "paper":
        n = c.number(m, "n_samples", mw, integer=True)
        if n < 3:
            raise c.fail(f"{mw}.n_samples", "must be at least 3")
        c.within(n, f"{mw}.n_samples", 3, MAX_SAMPLES, "samples")
        x0 = c.within(c.number(m, "x_start_mm", mw), f"{mw}.x_start_mm", lo, hi, "mm")
        if c.number(m, "spacing_mm", mw) <= 0:
            raise c.fail(f"{mw}.spacing_mm", "must be positive")
        c.within(x0 + (n - 1) * m["spacing_mm"], f"{mw}: the last sample (x_start_mm + (n_samples - 1) * spacing_mm)",
                 lo, hi, "mm")
        c.errors_um([c.number(m, "mean_um", mw)], f"{mw}.mean_um", indexed=False)
        c.number(m, "n_params", mw, integer=True)
        k = c.numbers(m, "k", mw, integer=True)
        c.errors_um(c.numbers(m, "amplitude_um", mw, length=len(k)), f"{mw}.amplitude_um")
        c.numbers(m, "phase_rad", mw, length=len(k))
        if any(not 0 < x < n for x in k):
            raise c.fail(f"{mw}.k", f"frequencies must lie between 1 and {n - 1}")
        return paper_from_json(leg, stroke, spacing, stats, m)
    b = c.get(m, "basis", mw)
    bw = f"{mw}.basis"
    c.within(c.number(b, "center_mm", bw), f"{bw}.center_mm", lo, hi, "mm")
    if c.number(b, "half_span_mm", bw) <= 0:
        raise c.fail(f"{bw}.half_span_mm", "must be positive")
    c.within(b["half_span_mm"], f"{bw}.half_span_mm", 1e-3, hi - lo, "mm")
    td = c.number(b, "trend_degree", bw, integer=True)
    rd = c.number(b, "reversal_degree", bw, integer=True)
    wl = c.numbers(b, "wavelengths_mm", bw)
    lead = c.number(b, "lead_mm", bw, optional=True)
    lh = c.number(b, "lead_harmonics", bw, integer=True)
    if not (0 <= td <= 10 and -1 <= rd <= 10 and 0 <= lh <= MAX_LEAD_HARMONICS and len(wl) <= MAX_WAVES):
        raise c.fail(bw, f"degrees out of range (trend {td}, reversal {rd}, lead harmonics {lh}, "
                         f"{len(wl)} stroke harmonics)")
    if any(w <= 0 for w in wl) or (lead is not None and lead <= 0) or (lh > 0 and lead is None):
        raise c.fail(bw, "wavelengths and lead must be positive, and lead harmonics need a lead")
    for i, w in enumerate(wl + ([lead] if lead is not None else [])):
        name = f"{bw}.wavelengths_mm[{i}]" if i < len(wl) else f"{bw}.lead_mm"
        c.within(w, name, 1e-3, 10 * (hi - lo), "mm")
    n_params = (td + 1) + (rd + 1) + 2 * len(wl) + 2 * lh
    c.errors_um(c.numbers(m, "coefficients_um", mw, length=n_params), f"{mw}.coefficients_um")
    if m.get("reversal_um") is not None:
        c.errors_um([c.number(m, "reversal_um", mw)], f"{mw}.reversal_um", indexed=False)
    if not isinstance(m.get("selection", {}), dict):
        raise c.fail(f"{mw}.selection", "expected an object")
    return bidirectional_from_json(leg, stroke, spacing, stats, m)


def load_model(path: str | os.PathLike) -> LegErrorModel:
    """Read and check a model file; `SchemaError` (naming the file and field) if it is corrupt
    or foreign. `FileNotFoundError` if it does not exist."""
    path = Path(path)
    raw = path.read_bytes()
    c = _Checker(path)
    try:
        doc = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise SchemaError(wrong_kind(path, "model", _NOT_A_MODEL) or
                          f"{path}: not a text file (a model file is JSON written by `station fit`)") from None
    except json.JSONDecodeError as exc:
        other = wrong_kind(path, "model", _NOT_A_MODEL)  # a table given where a model is expected, ...
        if other:
            raise SchemaError(other) from None
        raise SchemaError(f"{path}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg}); "
                          "the file is truncated or corrupt: fit the recording again") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        found = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise SchemaError(f"{path}: not a leg-error model (format is {found!r}, expected {FORMAT!r})")
    version = doc.get("version")
    if version != VERSION:
        raise SchemaError(f"{path}: model format version {version!r} is not supported (this station reads "
                          f"version {VERSION}); fit the recording again with this version")
    method = c.get(doc, "method", "")
    if method not in METHODS:
        raise c.fail("method", f"unknown method {method!r} (known: {', '.join(METHODS)})")
    source = c.get(doc, "source", "")
    if not isinstance(source, dict) or not isinstance(source.get("path", ""), str) or not isinstance(source.get("sha256", ""), str):
        raise c.fail("source", "expected {\"path\": ..., \"sha256\": ...}")
    legs_doc = c.get(doc, "legs", "")
    if not isinstance(legs_doc, dict) or not legs_doc:
        raise c.fail("legs", "expected a non-empty object of legs")
    legs: dict[int, LegFit] = {}
    for key, d in legs_doc.items():
        if not key.isdigit() or int(key) not in LEG_NUMBERS:
            raise c.fail(f"legs.{key}", f"leg keys must be leg numbers {LEG_NUMBERS[0]} .. {LEG_NUMBERS[-1]}")
        try:
            legs[int(key)] = _leg(c, method, int(key), d)
        except SchemaError:
            raise
        except (KeyError, TypeError, ValueError) as exc:
            raise c.fail(f"legs.{key}", f"malformed ({exc})") from None
    options = doc.get("options", {})
    identity = doc.get("identity", {})
    if not isinstance(identity, dict) or not isinstance(identity.get("legs", {}), dict):
        raise c.fail("identity", "expected {\"station\": ..., \"operator\": ..., \"legs\": {...}}")
    for key, leg in identity.get("legs", {}).items():
        if not isinstance(leg, dict) or not all(v is None or isinstance(v, str) for v in leg.values()):
            raise c.fail(f"identity.legs.{key}", "expected {\"serial\": text or null, ...}")
    try:  # last: an edited field no model has is named by its own check above
        integrity = check_json_record(path, doc, "legs", len(legs_doc), REMAKE)
    except IntegrityError as exc:
        raise SchemaError(str(exc)) from None
    model = LegErrorModel(method, legs, source={"path": source.get("path", ""), "sha256": source.get("sha256", "")},
                          options=options if isinstance(options, dict) else {},
                          created_utc=str(doc.get("created_utc", "")), identity=identity)
    model.integrity = integrity
    return model
