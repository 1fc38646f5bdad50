"""`station report`: PNG plots and a summary table of a session, before and after a model."""

from __future__ import annotations

import argparse

from procedures.errors import InputError
from procedures.fit import load_model
from procedures.recording.reader import read_session
from procedures.report import make_report
from station.commands.fit import _lead

NAME = "report"
HELP = "plots (PNG) and a summary (Markdown, JSON) of a session before and after compensation"
DESCRIPTION = (
    "Write errors.png, residuals.png, histograms.png (before/after, like the paper's Figs. 7-8), "
    "spectrum.png (residual spectrum, screw lead marked), summary.md and summary.json into DIR. "
    "Without --model the default model is fitted to the session."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("session", metavar="FILE.h5", help="recorded session")
    p.add_argument("--out", required=True, metavar="DIR", help="directory for the report files (created)")
    p.add_argument("--model", metavar="MODEL.json", help="model to compensate with (default: fit the default model)")
    p.add_argument("--lead-mm", type=_lead, default="auto", metavar="MM|auto|none",
                   help="screw lead to mark (and to fit with, without --model); default auto")


def run(args) -> int:
    session = read_session(args.session)
    if session.points.size == 0:
        raise InputError(f"{session.path}: the session has no points; record a sweep first")
    model = load_model(args.model) if args.model else None
    result = make_report(session.points, args.out, model, source_path=str(session.path),
                         source_sha256=session.sha256, lead_mm=args.lead_mm)
    if model is not None and not result.summary["model"]["fitted_to_this_session"]:
        print(f"note: the model was fitted to {model.source.get('path') or 'another recording'}, "
              "not to this session: the residual figures are a true test of it")
    for row in result.summary["legs"]:
        rr = row["residual_range_reduction_pct"]
        print(f"leg {row['leg']}: range before {row['range_before_um']:.3f} um, residual range {row['residual_range_um']:.3f} um"
              + (f" (residual range reduction {rr:.1f} %)" if rr is not None else "")
              + f"; RMS before {row['rms_before_um']:.3f} um, residual RMS {row['residual_rms_um']:.3f} um")
    print(f"residual = error minus model on this session's points: {result.summary['residuals']}; "
          "figures: docs/figures.md")
    for path in result.files:
        print(f"wrote {path}")
    return 0
