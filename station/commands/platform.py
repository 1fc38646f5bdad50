"""`station platform`: what the recorded leg errors, and their compensation, do to the platform pose.

The seed paper's Section 4 experiment (procedures.platform.experiment) on a session file or a
fitted model, written as a Markdown + JSON report (the paper's Tables 1 and 2) and histograms
(its Figs. 9 and 10). Loading the inputs and writing the report live in station/services/platform_jobs.py,
which the terminal UI's Platform page uses too.
"""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse

NAME = "platform"
HELP = "pose errors of the platform from leg errors, before and after compensation (paper's Table 2)"
DESCRIPTION = (
    "Simulate random platform poses: inverse kinematics gives the leg positions, the recorded leg "
    "errors (per direction, interpolated) are added, forward kinematics gives the erroneous pose; "
    "then again with the compensation applied. The compensation is a model (MODEL.json from "
    "`station fit`), a table (TABLE.csv from `station table`, applied as the drive interpolates "
    "it; give --recording), or with FILE.h5 alone the mean of the other passes. With a model or a "
    "table the measured leg error is the recording's systematic error (mean of its passes, the "
    "paper's setting) and, on the same poses, one recorded pass (repeatability included); both are "
    "reported. The recorded error is taken on the compensation's basis, as `station fit` and `station report` "
    "use it: with a model, the error it was fitted to (normalised to 20 degC material temperature, or raw for "
    "a model fitted with --raw); with a table or FILE.h5 alone normalised to 20 degC unless --raw. "
    "Writes platform_report.md, platform_summary.json and histograms to --out."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", type=V.IN_FILE.argtype(), metavar="FILE.h5|MODEL.json|TABLE.csv",
                   help="a session file, a model file from `station fit`, or a table from `station table`")
    p.add_argument("--out", type=V.OUT_DIR.argtype(), required=True, metavar="DIR", help="directory for the report and figures (created)")
    p.add_argument("--force", action="store_true", help="replace the output if it exists (default: refused)")
    p.add_argument("--poses", type=V.POSES.argtype(), default=2000, metavar="N", help="random poses (default 2000)")
    p.add_argument("--seed", type=V.SEED.argtype(), default=0, metavar="S", help="random seed (default 0)")
    p.add_argument("--recording", type=V.SESSION.argtype(), metavar="FILE.h5", help="the session giving the measured errors (needed with "
                   "TABLE.csv; with MODEL.json the default is the recording named in the model)")
    p.add_argument("--measured", choices=["pass", "mean"], default=None,
                   help="the measurement of the main tables: 'mean' = the systematic error, mean of all passes per "
                   "direction (the paper's setting; default with MODEL.json or TABLE.csv), 'pass' = one recorded pass per "
                   "pose and leg (the only one with FILE.h5 alone); with a model or table the other is reported beside it")
    p.add_argument("--profile", type=V.PROFILE.argtype(), metavar="PROFILE.toml",
                   help="with TABLE.csv: drive profile whose table limits the table is checked against (default: built-in)")
    p.add_argument("--raw", action="store_true",
                   help="use the recording's raw error, not normalised to 20 degC (for a table made from a model "
                        "fitted with `station fit --raw`); refused with a MODEL.json fitted to the normalised error")
    p.add_argument("--geometry", type=V.TOML_FILE.argtype(), metavar="FILE.toml", help="platform geometry (default: the paper-like positioner, docs/platform.md)")
    p.add_argument("--xy-mm", type=V.HALF_RANGE_MM.argtype(), default=60.0, help="workspace half-range in x and y about home, mm (default 60)")
    p.add_argument("--z-mm", type=V.HALF_RANGE_MM.argtype(), default=60.0, help="workspace half-range in z about home, mm (default 60)")
    p.add_argument("--tilt-deg", type=V.TILT_DEG.argtype(), default=3.0, help="workspace half-range of rx and ry, degrees (default 3)")
    p.add_argument("--yaw-deg", type=V.YAW_DEG.argtype(), default=0.0, help="workspace half-range of rz, degrees (default 0)")


def run(args) -> int:
    from station.services.platform_jobs import PlatformRequest, prepare_platform

    job = prepare_platform(PlatformRequest(
        args.poses, args.seed, source=args.source, recording=args.recording, measured=args.measured,
        profile=args.profile, raw=args.raw, geometry=args.geometry, xy_mm=args.xy_mm, z_mm=args.z_mm,
        tilt_deg=args.tilt_deg, yaw_deg=args.yaw_deg, out=args.out, force=args.force))
    for line in job.lines:
        print(line, flush=True)
    for line in job.run().lines:
        print(line)
    return 0
