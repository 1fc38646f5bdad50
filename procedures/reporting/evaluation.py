"""The one evaluation of a session (issue 33.3): its ISO 230-2 values, the expanded uncertainty U
(k = 2) of each with the whole budget, U of every target's mean deviation, and the ISO 14253-1
decision of each leg at the session's stage. The report (iso230-2.json), the certificate, the
catalog's record of the session (and so the web's fleet, charts and comparison) and `station
compare` all read their figures from `evaluate_session`; the content is
procedures.reporting.iso230_report.build's (that module's docstring says what each key holds).

The session is a procedures.io.recording.reader.Session: its identity was parsed once, by the
reader; nothing here re-opens the file. What depends on a station's config (the tolerances of
`--config` instead of the recorded ones) is station/services' to pass in.

Deviations are measured minus target (um); positions in mm.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from procedures.io.recording.stage import AS_LEFT
from procedures.reporting import decision, iso230_report


def decision_stage(session_stage: str | None) -> str:
    """The stage a session is decided at: as left for an as-left verification, as found for
    everything else (an adjustment or a sweep of stage other is read against the as-found limits)."""
    return decision.STAGES[1] if session_stage == AS_LEFT else decision.STAGES[0]


def evaluate_session(session: Any, raw: bool = False, tolerances: dict | None = None,
                     stage: str | None = None) -> dict[str, Any]:
    """The evaluation of `session` (module docstring) on the error normalised to 20 degC (`raw`:
    the recorded error), decided against `tolerances` ({leg type: Tolerance.to_json()}; None:
    those the session recorded) at `stage` ("as_found" / "as_left"; None: the session's own,
    `decision_stage`). A JSON-able dict."""
    identity = session.identity.to_json() if session.identity.recorded else None
    return evaluate_points(session.points, plan=session.plan, devices=session.devices,
                           station_config=session.station_config, attrs=session.attrs,
                           source={"path": str(session.path), "sha256": session.sha256}, raw=raw,
                           identity=identity, tolerances=tolerances,
                           stage=stage or decision_stage(getattr(session, "stage", None)))


def evaluate_points(points: np.ndarray, *, plan: dict, devices: dict, station_config: dict,
                    identity: dict | None, source: dict, attrs: dict | None = None, raw: bool = False,
                    tolerances: dict | None = None, stage: str) -> dict[str, Any]:
    """The same evaluation of points not read from a file: a verification's points as it
    measured them, with the plan, devices, config and identity its recording holds (`attrs`: the
    recording's root attributes, None when not at hand: the identification then says less, the
    values and decisions are the same)."""
    return iso230_report.build(points, plan=plan, devices=devices, station_config=station_config, attrs=attrs or {},
                               source=source, raw=raw, identity=identity, tolerances=tolerances, stage=stage)


def leg_values(evaluation: dict, leg: int | str) -> dict[str, dict[str, float | None]]:
    """{value name: {"value_um", "U_um"}} of one leg ({} for a leg the evaluation does not hold)."""
    entry = evaluation["legs"].get(str(leg)) or {}
    return {name: {"value_um": v["value_um"], "U_um": v["U_um"]} for name, v in (entry.get("values") or {}).items()}


def leg_targets(evaluation: dict, leg: int | str) -> list[list]:
    """[direction "up"/"down", target mm, mean deviation um, U of that mean um] of every target
    of one leg: what a comparison of stations reads, target by target (E_n)."""
    entry = evaluation["legs"].get(str(leg)) or {}
    return [[t["direction"], t["target_mm"], t["mean_um"], t["U_um"]] for t in entry.get("targets") or []]


def leg_verdict(evaluation: dict, leg: int | str) -> str | None:
    """The leg's overall ISO 14253-1 verdict, None when no tolerance decides it (its type has none)."""
    d = ((evaluation.get("decisions") or {}).get("legs") or {}).get(str(leg))
    if not d or d["overall"] == decision.NO_TOLERANCE:
        return None
    return d["overall"]
