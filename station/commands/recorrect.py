"""`station recorrect`: redo a session's air refractive-index correction into a new file."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse

from station.services.recorrect_job import EQUATIONS

NAME = "recorrect"
HELP = "re-correct a session's laser readings for the air refractive index (Ciddor/Edlen) into a new file"
DESCRIPTION = (
    "Replace the refractive index the interferometer applied (its record in the session) by the one the "
    "station computes (Ciddor 1996 or modified Edlen, NIST) from the recorded air temperature, pressure, "
    "humidity and CO2, corrected or replaced by the options, for the configured vacuum wavelength, and "
    "correct for the configured dead path. Writes a NEW session file stating what was done (source file and "
    "SHA-256, equation, inputs); the original stays untouched. A session without the instrument's record is "
    "refused. See docs/metrology.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("session", type=V.SESSION.argtype(), metavar="SESSION.h5", help="recorded session (not changed)")
    p.add_argument("--out", type=V.OUT_FILE.argtype(), required=True, metavar="NEW.h5", help="the re-corrected session file to write")
    p.add_argument("--force", action="store_true", help="replace --out if it exists (default: refused)")
    p.add_argument("--equation", choices=EQUATIONS, default="ciddor", help="refractive-index equation (default ciddor)")
    air = p.add_mutually_exclusive_group()
    air.add_argument("--air-temp-offset-c", type=V.TEMP_OFFSET_K.argtype(), default=0.0, metavar="K",
                     help="add this to every recorded air temperature (a sensor found reading low by K: +K)")
    air.add_argument("--air-temp-c", type=V.AIR_TEMP_C.argtype(), metavar="C", help="use this air temperature for every point")
    p.add_argument("--pressure-pa", type=V.PRESSURE_PA.argtype(), metavar="PA", help="use this air pressure (Pa) for every point")
    p.add_argument("--humidity-pct", type=V.HUMIDITY_PCT.argtype(), metavar="RH", help="use this relative humidity (%%RH) for every point")
    p.add_argument("--co2-ppm", type=V.CO2_PPM.argtype(), metavar="PPM",
                   help="CO2 where the session has no reading (default: the config's [metrology] co2_ppm, 450)")
    p.add_argument("--dead-path-mm", type=V.DEAD_PATH_MM.argtype(), metavar="MM",
                   help="laser dead path (default: the config's [metrology] dead_path_mm, 0)")
    p.add_argument("--wavelength-nm", type=V.WAVELENGTH_NM.argtype(), metavar="NM",
                   help="the laser's vacuum wavelength (default: the config's [metrology] wavelength_nm, 632.991)")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML whose [metrology] gives the defaults")


def run(args) -> int:
    from station.services.recorrect_job import RecorrectRequest, prepare_recorrect

    job = prepare_recorrect(RecorrectRequest(
        args.session, args.out, force=args.force, equation=args.equation, air_temp_offset_c=args.air_temp_offset_c,
        air_temp_c=args.air_temp_c, pressure_pa=args.pressure_pa, humidity_pct=args.humidity_pct,
        co2_ppm=args.co2_ppm, dead_path_mm=args.dead_path_mm, wavelength_nm=args.wavelength_nm, config=args.config))
    for line in job.run().lines:
        print(line)
    return 0
