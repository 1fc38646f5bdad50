"""`station fit`: fit a leg-error model to a recorded session and save it as JSON."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse

from station.services.fit_job import DEFAULT_N_PARAMS

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
    from station.services.fit_job import FitRequest, prepare_fit

    job = prepare_fit(FitRequest(args.session, args.out, force=args.force, method=args.method, params=args.params,
                                 lead_mm=args.lead_mm, legs=args.legs, config=args.config, raw=args.raw))
    r = job.run().data
    for line in r.basis_lines + r.notes:
        print(line)
    print(f"method: {r.method}" + (f" ({r.params} cosine terms)" if r.method == "paper" else ""))
    print(f"{'leg':>3}  {'held-out RMS':>12}  {'noise floor':>11}  {'held-out ratio':>14}  {'(ideal)':>7}  "
          f"{'range before':>12}  {'held-out range':>14}  {'held-out range reduction':>24}  terms")
    for leg, f in r.model.legs.items():
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
        if leg in r.probes:
            print(f"     {r.probes[leg]}")
    print("held-out: each cycle scored by a model fitted without it; held-out ratio = held-out RMS / noise floor;"
          " (ideal) = the held-out ratio a perfect static model would score; held-out range = max - min of the"
          " held-out residuals (figures: docs/figures.md)")
    print(f"model: {r.path}")
    print(f"next: station table {r.path} --out table.csv   |   station report {r.session_path} --out report --model {r.path}")
    return 0
