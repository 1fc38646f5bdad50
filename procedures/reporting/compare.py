"""Do stations agree? A comparison of sessions of one reference leg measured by several stations
(ISO/IEC 17043, ISO 13528), from their ISO 230-2 reports (procedures.reporting.iso230_report.build: the mean
deviation x of every target and direction with the expanded uncertainty U of that mean, k = 2).
docs/decisions.md.

Per target and direction, for every pair of stations A, B:

    E_n = (x_A - x_B) / sqrt(U_A^2 + U_B^2)

When U is an honest k = 2 uncertainty, |E_n| > 1 happens at a target by chance with probability
about P_CHANCE (5 %). A pair disagrees when its count of |E_n| > 1 over all targets (both
directions) is at least the critical count: the smallest k with P(X >= k) <= ALPHA for X binomial
(n targets, P_CHANCE). A station is flagged when it disagrees with more than half of the others:
with two stations a disagreement flags both (only a third can tell which one is off); with three,
a biased station disagrees with both others, while each of those disagrees with it alone.
Targets of one session share the laser's scale and air terms, so they are not fully
independent: the rule is a screen, the per-target table is the evidence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from procedures.vocabulary import InputError

P_CHANCE = 0.05
ALPHA = 0.05
TARGET_TOLERANCE_MM = 0.001


@dataclass(frozen=True)
class StationRun:
    """One station's measurement of the reference leg: `targets` are (direction "up"/"down",
    target_mm, mean_um, U_um) from its ISO 230-2 report; `values` the ISO values {name: {value_um, U_um}}."""

    label: str  # unique in the comparison: "station-id (session name)"
    station_id: str
    session: str
    leg: int
    serial: str
    targets: tuple[tuple[str, float, float, float], ...]
    values: dict[str, dict[str, Any]]
    stage: str | None = None  # procedures/io/recording/stage.py: only sessions of one stage compare


def e_n(x_a: float | None, u_a: float | None, x_b: float | None, u_b: float | None) -> float | None:
    """E_n = (x_A - x_B) / sqrt(U_A^2 + U_B^2), the one formula `station compare` and the web's
    /compare use; inf for different values with both U zero, None without both values and U."""
    if x_a is None or x_b is None or u_a is None or u_b is None:
        return None
    den = math.hypot(u_a, u_b)
    if den > 0:
        return (x_a - x_b) / den
    return 0.0 if x_a == x_b else math.inf


STAGE_WORDS = {"as_found": "an as-found calibration", "as_left": "an as-left verification",
               "adjustment": "an adjustment", "other": "a session of stage other"}


def same_stage(runs: list[tuple[str, str | None]]) -> None:
    """InputError (one line, naming both sessions) unless every (session name, stage) is of one stage: a calibration
    as found and a verification as left measure different legs (before and after compensation),
    so their difference is the compensation, not a station's bias."""
    (a, sa), *rest = runs
    for b, sb in rest:
        if sb != sa:
            raise InputError(f"{a} is {STAGE_WORDS.get(sa, f'of stage {sa}')} but {b} is "
                             f"{STAGE_WORDS.get(sb, f'of stage {sb}')}: compare sessions of the same stage "
                             "(as found with as found, as left with as left)")


def within_window(runs: list[tuple[str, str | None]], window_days: float) -> None:
    """InputError (one line, naming both sessions) when two of (session name, start time UTC
    text) started more than `window_days` apart: the web's /compare does not compare such a pair
    either ([catalog] compare_window_days); the difference of sessions months apart is the leg's
    drift or wear, not a station's bias. A session without a readable start time is not refused."""
    import datetime as dt

    def when(text):
        try:
            t = dt.datetime.fromisoformat(str(text).replace("Z", "+00:00"))
        except ValueError:
            return None
        return t if t.tzinfo else t.replace(tzinfo=dt.timezone.utc)

    timed = [(name, when(t)) for name, t in runs if t]
    timed = [(name, t) for name, t in timed if t is not None]
    for i, (a, ta) in enumerate(timed):
        for b, tb in timed[i + 1:]:
            days = abs((tb - ta).total_seconds()) / 86400.0
            if days > window_days:
                raise InputError(f"{a} and {b} were measured {days:.0f} days apart, beyond the comparison window of "
                                 f"{window_days:g} days ([catalog] compare_window_days of --config): compare sessions "
                                 "of one period, or widen the window")


def binomial_tail(k: int, n: int, p: float) -> float:
    """P(X >= k) for X ~ Binomial(n, p)."""
    return sum(math.comb(n, i) * p ** i * (1 - p) ** (n - i) for i in range(max(k, 0), n + 1))


def critical_count(n: int, p: float = P_CHANCE, alpha: float = ALPHA) -> int:
    """The smallest k with P(X >= k) <= alpha (X ~ Binomial(n, p)): that many |E_n| > 1 in n
    targets are more than chance allows."""
    for k in range(n + 1):
        if binomial_tail(k, n, p) <= alpha:
            return k
    return n + 1


def _matched(runs: list[StationRun]) -> list[tuple[str, float, list[tuple[float, float]]]]:
    """(direction, target_mm, [(mean_um, U_um) per run]) at the targets every run measured."""
    out = []
    for d, t, _, _ in runs[0].targets:
        row = []
        for r in runs:
            hit = [(m, u) for dd, tt, m, u in r.targets if dd == d and abs(tt - t) <= TARGET_TOLERANCE_MM]
            if not hit:
                break
            row.append(hit[0])
        else:
            out.append((d, t, row))
    return out


def _pair(a: StationRun, b: StationRun, ia: int, ib: int, matched) -> dict[str, Any]:
    rows, exceed = [], 0
    for d, t, row in matched:
        (xa, ua), (xb, ub) = row[ia], row[ib]
        en = e_n(xa, ua, xb, ub)
        exceed += abs(en) > 1
        rows.append({"direction": d, "target_mm": t, "x_a_um": xa, "U_a_um": ua, "x_b_um": xb, "U_b_um": ub,
                     "d_um": xa - xb, "E_n": en if math.isfinite(en) else None})
    n = len(rows)
    k = critical_count(n)
    by_dir = {d: sum(1 for r in rows if r["direction"] == d and (r["E_n"] is None or abs(r["E_n"]) > 1))
              for d in ("up", "down")}
    mean_d = {d: (sum(r["d_um"] for r in rows if r["direction"] == d) /
                  max(1, sum(1 for r in rows if r["direction"] == d))) for d in ("up", "down")}
    return {"a": a.label, "b": b.label, "n_targets": n, "exceed": exceed, "exceed_by_direction": by_dir,
            "share_within_pct": 100.0 * (n - exceed) / n, "critical_count": k,
            "chance_tail_p": binomial_tail(exceed, n, P_CHANCE), "disagree": exceed >= k,
            "mean_difference_um": mean_d, "rows": rows}


def compare_pair(label_a: str, targets_a, label_b: str, targets_b) -> dict[str, Any]:
    """One pair of stations' comparison, target by target (what `compare` gives every pair, and
    the web's /compare shows for a leg): `targets_*` are (direction, target_mm, mean_um, U_um) of
    each side's session; rows at the targets both measured, E_n (`e_n`), counts and verdict."""
    a = StationRun(label_a, label_a, label_a, 0, "", tuple(tuple(t) for t in targets_a), {})
    b = StationRun(label_b, label_b, label_b, 0, "", tuple(tuple(t) for t in targets_b), {})
    matched = _matched([a, b])
    if not matched:
        return {"a": label_a, "b": label_b, "n_targets": 0, "exceed": 0, "rows": [], "disagree": False}
    return _pair(a, b, 0, 1, matched)


def compare(runs: list[StationRun]) -> dict[str, Any]:
    """The comparison (module docstring) as a JSON-able dict: every pair of stations with its
    rows (direction, target, x and U of both, d, E_n), counts, critical count and verdict; every
    station flagged or not, and the stations it disagrees with; the rule in words."""
    if len(runs) < 2:
        raise InputError("a comparison needs at least two sessions")
    serials = {r.serial for r in runs}
    if len(serials) != 1:
        a, b = runs[0], next(r for r in runs if r.serial != runs[0].serial)
        raise InputError(f"{a.session} measured leg {a.serial} but {b.session} measured leg {b.serial}: a station "
                         "comparison needs the same reference leg (same serial) in every session")
    same_stage([(r.session, r.stage) for r in runs])
    matched = _matched(runs)
    if not matched:
        raise InputError(f"{runs[0].session} and the other sessions share no target position (within "
                         f"{TARGET_TOLERANCE_MM * 1000:g} um): sweep the same plan on every station")
    pairs = [_pair(runs[i], runs[j], i, j, matched) for i in range(len(runs)) for j in range(i + 1, len(runs))]
    stations = []
    for r in runs:
        against = [p["b"] if p["a"] == r.label else p["a"] for p in pairs if r.label in (p["a"], p["b"]) and p["disagree"]]
        stations.append({"label": r.label, "station_id": r.station_id, "session": r.session, "leg": r.leg,
                         "disagrees_with": against, "flagged": len(against) > (len(runs) - 1) / 2})
    return {"serial": runs[0].serial, "n_stations": len(runs), "p_chance": P_CHANCE, "alpha": ALPHA,
            "rule": (f"E_n = (x_A - x_B) / sqrt(U_A^2 + U_B^2) per target and direction for every pair of stations; "
                     f"a pair disagrees when |E_n| > 1 at k or more of its n targets, k the smallest count with "
                     f"P(X >= k) <= {ALPHA:g} for X ~ Binomial(n, {P_CHANCE:g}) (the chance exceedance of an honest "
                     "k = 2 uncertainty); a station is flagged when it disagrees with more than half of the others"),
            "note": "; ".join(
                (["two stations: a disagreement flags both; a third station tells which one is off"] if len(runs) == 2
                 else [])
                + [f"{a.session} and {b.session} are both from station {a.station_id}: a repeat on one station, "
                   "not a comparison between stations" for i, a in enumerate(runs) for b in runs[i + 1:]
                   if a.station_id == b.station_id]),
            "pairs": pairs, "stations": stations}


def markdown(c: dict[str, Any]) -> str:
    lines = [f"# Station comparison: reference leg {c['serial']}", "", f"Rule: {c['rule']}.", ""]
    if c["note"]:
        lines += [f"Note: {c['note']}.", ""]
    lines += ["| station | session | flagged | disagrees with |", "|---|---|---|---|"]
    for s in c["stations"]:
        lines.append(f"| {s['station_id']} | {s['session']} | {'YES' if s['flagged'] else 'no'} | "
                     f"{', '.join(s['disagrees_with']) or '-'} |")
    lines += ["", "| A | B | targets | abs(E_n) > 1 (up / down) | within | critical count | disagree | "
              "mean A - B up / down (um) |", "|---|---|---|---|---|---|---|---|"]
    for p in c["pairs"]:
        lines.append(f"| {p['a']} | {p['b']} | {p['n_targets']} | {p['exceed']} ({p['exceed_by_direction']['up']} / "
                     f"{p['exceed_by_direction']['down']}) | {p['share_within_pct']:.1f} % | {p['critical_count']} | "
                     f"{'YES' if p['disagree'] else 'no'} | {p['mean_difference_um']['up']:+.3f} / "
                     f"{p['mean_difference_um']['down']:+.3f} |")
    for p in c["pairs"]:
        lines += ["", f"## {p['a']} against {p['b']}", "",
                  "| direction | target (mm) | x_A (um) | U_A (um) | x_B (um) | U_B (um) | x_A - x_B (um) | E_n |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in p["rows"]:
            en = "inf" if r["E_n"] is None else f"{r['E_n']:+.2f}"
            lines.append(f"| {r['direction']} | {r['target_mm']:.3f} | {r['x_a_um']:+.3f} | {r['U_a_um']:.3f} | "
                         f"{r['x_b_um']:+.3f} | {r['U_b_um']:.3f} | {r['d_um']:+.3f} | {en} |")
    return "\n".join(lines) + "\n"


def summary_lines(c: dict[str, Any]) -> list[str]:
    out = [f"reference leg {c['serial']}, {c['n_stations']} stations; rule: {c['rule']}"]
    for p in c["pairs"]:
        out.append(f"{p['a']} - {p['b']}: |E_n| > 1 at {p['exceed']} of {p['n_targets']} targets (up "
                   f"{p['exceed_by_direction']['up']}, down {p['exceed_by_direction']['down']}; critical count "
                   f"{p['critical_count']}), mean difference up {p['mean_difference_um']['up']:+.3f} um, down "
                   f"{p['mean_difference_um']['down']:+.3f} um: {'DISAGREE' if p['disagree'] else 'consistent'}")
    for s in c["stations"]:
        out.append(f"{s['label']}: " + ("FLAGGED (disagrees with " + ", ".join(s["disagrees_with"]) + ")"
                                        if s["flagged"] else "not flagged"))
    if c["note"]:
        out.append(f"note: {c['note']}")
    return out


def plot(c: dict[str, Any], path) -> None:
    """E_n per target, one line per pair of stations and direction, the +/-1 band drawn (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    for p in c["pairs"]:
        for d, marker in (("up", "^"), ("down", "v")):
            rows = [r for r in p["rows"] if r["direction"] == d and r["E_n"] is not None]
            ax.plot([r["target_mm"] for r in rows], [r["E_n"] for r in rows], marker, ms=5, linestyle="-", lw=0.6,
                    label=f"{p['a'].split(' (')[0]} - {p['b'].split(' (')[0]} {d}")
    ax.axhspan(-1, 1, color="tab:green", alpha=0.1)
    for y in (-1, 1):
        ax.axhline(y, color="tab:green", lw=0.8)
    ax.set_xlabel("target position (mm)")
    ax.set_ylabel("E_n = (x_A - x_B) / sqrt(U_A² + U_B²)")
    ax.set_title(f"Station comparison, reference leg {c['serial']}", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
