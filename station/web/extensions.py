"""What the web view takes from the rest of the station: the tolerances of each leg type and
the certificates issued for a leg.

- `tolerances_of(config_path)`: `[tolerances.TYPE]` limits in um per leg type, as the station
  config reads them (procedures.reporting.decision.parse_tolerances via station.services.config.load_config: a bad
  section is refused naming file, section and key); the as-left limits, since a fleet in service is
  judged as left. A type without a limit has no tolerance line and no Cpk, and the page says so.
- `certificates_of(runs_dir, serial)`: the certificates `station certificate` issued for a leg,
  every revision listed in `runs_dir/certificates/REPORT.index.json` whose serial is the leg's
  (station.services.certificate_jobs), superseded revisions marked.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from station.services.config import tolerances_of_config

CHART_FIGURES = ("E", "B", "R")

decision_tolerances_of = tolerances_of_config
"""{leg type: Tolerance} of the station TOML (both stages), for the fleet's ISO 14253-1
decisions; {} without a config (station.services.config.tolerances_of_config)."""


def tolerances_of(config_path: str | Path | None) -> dict[str, dict[str, float]]:
    """{leg type: {figure: as-left upper limit um}} of the station TOML; {} without a config."""
    return {t: tol.limits("as_left") for t, tol in decision_tolerances_of(config_path).items() if tol.limits("as_left")}


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
    from station.services.certificate_jobs import FOLDER_NAME  # noqa: PLC0415

    if not runs_dir:
        return []
    root = Path(runs_dir) / FOLDER_NAME
    found: list[Certificate] = []
    if not root.is_dir():
        return found
    for index_path in sorted(root.glob("*.index.json")):
        try:
            index = json.loads(index_path.read_text())
            revisions = list(index["revisions"])
        except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError):
            continue  # not an index the certificate command wrote: nothing to offer from it
        for rev in revisions:
            if not isinstance(rev, dict) or rev.get("serial") != serial:
                continue
            pdf = rev.get("pdf")
            if not isinstance(pdf, str) or Path(pdf).name != pdf or not (root / pdf).is_file():
                continue
            found.append(Certificate(pdf_name=pdf, pdf_path=root / pdf, number=str(index.get("report_no") or ""),
                                     revision=str(rev.get("revision") or ""), issued_utc=str(rev.get("issued_utc") or ""),
                                     superseded=rev.get("status") == "superseded"))
    return sorted(found, key=lambda c: (c.issued_utc, c.pdf_name))
