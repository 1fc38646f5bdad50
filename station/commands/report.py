"""`station report`: PNG plots and a summary table of a session, before and after a model, and
its ISO 230-2 test report with the expanded uncertainty of every value (Markdown, JSON, PDF)."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse

NAME = "report"
HELP = "plots, a summary before/after compensation and the ISO 230-2 test report with uncertainties (Markdown, JSON, PDF)"
DESCRIPTION = (
    "Write errors.png, residuals.png, histograms.png (before/after, like the paper's Figs. 7-8), "
    "spectrum.png (residual spectrum, screw lead marked), summary.md and summary.json into DIR, and the "
    "ISO 230-2 test report iso230-2.md/.json/.pdf with its graph iso230-2.png: identification, instrument and "
    "calibration date, environment, expansion coefficient and NDE, test parameters, compensation state, every "
    "value with its expanded uncertainty U (k = 2) and budget (docs/uncertainty.md). "
    "Without --model the default model is fitted to the session. Like `station fit`, everything uses the "
    "error normalised to 20 degC material temperature (--raw: the raw error); with --model, the error the "
    "model was fitted to (its error_basis; --raw with a normalised model is refused). docs/metrology.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("session", type=V.SESSION.argtype(), metavar="FILE.h5", help="recorded session")
    p.add_argument("--out", type=V.OUT_DIR.argtype(), required=True, metavar="DIR", help="directory for the report files (created)")
    p.add_argument("--force", action="store_true", help="replace the output if it exists (default: refused)")
    p.add_argument("--model", type=V.MODEL.argtype(), metavar="MODEL.json", help="model to compensate with (default: fit the default model)")
    p.add_argument("--lead-mm", type=V.LEAD_OR_AUTO_MM.argtype(), default="auto", metavar="MM|auto|none",
                   help="screw lead to mark (and to fit with, without --model), mm (> 0); default auto; none: no lead")
    p.add_argument("--raw", action="store_true",
                   help="use the raw error, not normalised to 20 degC (as `station fit --raw`); refused with a "
                        "--model fitted to the normalised error")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML whose catalog indexes the file written "
                   "(default: the built-in config: <runs>/catalog.sqlite; docs/catalog.md)")


def run(args) -> int:
    from station.services.report_jobs import ReportRequest, prepare_report

    job = prepare_report(ReportRequest(args.session, args.out, args.force, args.model, args.lead_mm, args.raw,
                                       args.config))  # the output checked before reading and fitting
    for line in job.run().lines:
        print(line)
    return 0
