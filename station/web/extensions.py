"""Extension points of the web view, kept small so they can be pointed at the full
implementations (tolerances and decisions, certificates) when those are merged.

- `tolerances_of(config_path)`: `[tolerances.TYPE]` limits in um per leg type, read tolerantly
  from the station TOML (`E_um`, `B_um`, `R_um`, ... each optional; an `as_left` sub-table, when
  present, wins over the top level, since a fleet is judged as left). A type without a limit has
  no tolerance line and no Cpk, and the page says so.
- `certificates_of(runs_dir, serial)`: the certificates issued for a leg: every
  `runs_dir/certificates/**/*.json` whose `serial` or `leg_serial` is the leg and whose `pdf`
  names a file beside it.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

CHART_FIGURES = ("E", "B", "R")


def _limits(table: dict) -> dict[str, float]:
    out: dict[str, float] = {}
    for name in ("E", "A", "B", "R", "M"):
        v = table.get(f"{name}_um")
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0:
            out[name] = float(v)
    return out


def tolerances_of(config_path: str | Path | None) -> dict[str, dict[str, float]]:
    """{leg type: {figure: upper limit um}} from `[tolerances.TYPE]` of the station TOML; {} when
    there is no file, no section or it cannot be read (the web view then shows no limits)."""
    if not config_path:
        return {}
    try:
        data = tomllib.loads(Path(config_path).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return {}
    section = data.get("tolerances")
    if not isinstance(section, dict):
        return {}
    out: dict[str, dict[str, float]] = {}
    for leg_type, table in section.items():
        if not isinstance(table, dict):
            continue
        limits = _limits(table)
        if isinstance(table.get("as_left"), dict):
            limits.update(_limits(table["as_left"]))
        if limits:
            out[str(leg_type)] = limits
    return out


@dataclass
class Certificate:
    pdf_name: str
    pdf_path: Path
    number: str
    revision: str
    issued_utc: str
    superseded: bool


def certificates_of(runs_dir: str | Path | None, serial: str) -> list[Certificate]:
    """The certificates of leg `serial` under `runs_dir/certificates/`, by issue time."""
    if not runs_dir:
        return []
    root = Path(runs_dir) / "certificates"
    found: list[Certificate] = []
    if not root.is_dir():
        return found
    for meta in sorted(root.rglob("*.json")):
        try:
            data = json.loads(meta.read_text())
        except (OSError, UnicodeDecodeError, ValueError):
            continue
        if not isinstance(data, dict) or serial not in (data.get("serial"), data.get("leg_serial")):
            continue
        pdf = data.get("pdf")
        if not isinstance(pdf, str) or Path(pdf).name != pdf or not (meta.parent / pdf).is_file():
            continue
        found.append(Certificate(pdf_name=pdf, pdf_path=meta.parent / pdf, number=str(data.get("number") or meta.stem),
                                 revision=str(data.get("revision") or ""), issued_utc=str(data.get("issued_utc") or ""),
                                 superseded=bool(data.get("superseded"))))
    return sorted(found, key=lambda c: (c.issued_utc, c.pdf_name))
