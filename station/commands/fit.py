"""`station fit`: fit a leg-error model to a recorded session and save it as JSON."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse

from procedures.vocabulary import InputError
from procedures.io.outputs import check_output_file
from procedures.fit.paper import DEFAULT_N_PARAMS
from procedures.vocabulary import Outcome

NAME = "fit"
HELP = "fit a leg-error model (default bidirectional, or the paper's Fourier model) to a session"
DESCRIPTION = (
    "Fit a leg-error model to a recorded session (FILE.h5) and save it as JSON naming the "
    "recording and its SHA-256. Per leg it prints the terms chosen, the held-out RMS (cross-"
    "validation over whole cycles), the noise floor from repeat passes, the held-out ratio and the "
    "held-out range reduction. See docs/models.md and docs/figures.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("session", type=V.SESSION.argtype(), metavar="FILE.h5", help="recorded session")
    p.add_argument("--out", type=V.OUT_FILE.argtype(), required=True, metavar="MODEL.json", help="model file to write")
    p.add_argument("--force", action="store_true", help="replace the output if it exists (default: refused)")
    p.add_argument("--method", choices=["default", "paper"], default="default",
                   help="default: bidirectional, size by cross-validation; paper: Algorithm 1 of the seed paper")
    p.add_argument("--params", type=V.COSINE_TERMS.argtype(), default=None, metavar="N",
                   help=f"--method paper only: number of cosine terms kept (default {DEFAULT_N_PARAMS}, as the paper; "
                        "at most what the recording's targets give)")
    p.add_argument("--lead-mm", type=V.LEAD_OR_AUTO_MM.argtype(), default="auto", metavar="MM|auto|none",
                   help="default method: screw lead for the once-per-revolution terms, mm (> 0); auto (default): look "
                        "for it in the data; none: no once-per-revolution terms")
    p.add_argument("--legs", type=V.LEGS.argtype(), help="fit only these legs, e.g. 1-3 or 2,5 (default: all in the session)")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML whose catalog indexes the file written "
                   "(default: the built-in config: <runs>/catalog.sqlite; docs/catalog.md)")
    p.add_argument("--raw", action="store_true",
                   help="fit the raw error (default: normalised to 20 degC material temperature, docs/metrology.md)")


def _fmt(value, spec: str = ".3f", none: str = "n/a") -> str:
    return none if value is None else format(value, spec)


def run(args) -> int:
    from procedures.acquisition.plans import parse_legs
    from procedures.acquisition.probe_rule import recorded_stop
    from procedures.fit.reversal_probes import ProbeReversal
    from procedures.io.recording.reader import read_session
    from station.services.analysis import analyse_session, save_session_model
    from station.services.config import load_config

    if args.params is not None and args.method != "paper":  # never silently ignored
        raise InputError(f"--params {args.params}: the number of cosine terms applies to --method paper only "
                         "(the default method sizes itself by cross-validation); drop --params or add --method paper")
    params_given = args.params is not None
    args.params = DEFAULT_N_PARAMS if args.params is None else args.params
    out = check_output_file(args.out, force=args.force)  # before the fit (procedures/io/outputs.py)
    session = read_session(args.session)
    if session.points.size == 0:
        raise InputError(f"{session.path}: the session has no points; record a sweep first")
    legs = parse_legs(args.legs) if args.legs else None
    analysis = analyse_session(session, args.raw, fit_method=args.method,
                               fit_options={"legs": legs, "n_params": args.params, "lead_mm": args.lead_mm})
    model = analysis.model
    if params_given:  # the paper method keeps at most the terms the targets give: more is refused, not ignored
        for leg, f in model.legs.items():
            most = (int(getattr(f, "n_samples", 0)) + 1) // 2 - 1
            if args.params > most:
                raise InputError(f"--params {args.params}: leg {leg} has {f.n_samples} targets per pass, which give "
                                 f"at most {most} cosine terms; give --params 1..{most}; nothing was written")
    save_session_model(model, out, session, load_config(args.config))
    for line in analysis.basis_lines:
        print(line)
    if session.outcome != Outcome.COMPLETED:
        print(f"note: the session's outcome is '{session.outcome}': the model uses the {session.points.size} points recorded")
    for key, state in sorted(session.devices.items()):
        if key.endswith("_compensation") and " points from " in state:
            print(f"warning: {key.split('_')[0].replace('leg', 'leg ')} was recorded with a compensation table "
                  f"active ({state}): this model describes the compensated leg, and a table made from it "
                  "replaces the active one instead of adding to it")
    print(f"method: {args.method}" + (f" ({args.params} cosine terms)" if args.method == "paper" else ""))
    print(f"{'leg':>3}  {'held-out RMS':>12}  {'noise floor':>11}  {'held-out ratio':>14}  {'(ideal)':>7}  "
          f"{'range before':>12}  {'held-out range':>14}  {'held-out range reduction':>24}  terms")
    for leg, f in model.legs.items():
        s = f.stats
        rr = s.heldout_range_reduction_pct
        print(
            f"{leg:>3}  {_fmt(s.heldout_rms_um):>9} um  {_fmt(s.noise_floor_um):>8} um  {_fmt(s.heldout_ratio, '.2f'):>14}  "
            f"{_fmt(s.ideal_heldout_ratio, '.2f'):>7}  {s.range_before_um:>9.3f} um  {_fmt(s.heldout_range_um):>11} um  "
            f"{_fmt(rr, '.1f') + ' %' if rr is not None else 'n/a':>24}  {f.describe()}"
        )
        if s.note:
            print(f"     note: {s.note}")
        if s.dropped:
            print(f"     note: {s.dropped} point(s) without a finite error were left out")
        probes = getattr(f, "selection", {}).get("reversal_probes")
        if probes:
            why = recorded_stop(session.plan, probes["pairs"], probes["stderr_um"])
            print(f"     {ProbeReversal(**probes).describe()}" + (f"; probes stopped: {why}" if why else ""))
    print("held-out: each cycle scored by a model fitted without it; held-out ratio = held-out RMS / noise floor;"
          " (ideal) = the held-out ratio a perfect static model would score; held-out range = max - min of the"
          " held-out residuals (figures: docs/figures.md)")
    print(f"model: {out}")
    print(f"next: station table {out} --out table.csv   |   station report {session.path} --out report --model {out}")
    return 0
