"""The re-correction job (issue 32 part 1, one shape for every job): `station recorrect` fills a
`RecorrectRequest`; `prepare_recorrect` checks the output and takes the defaults the request
leaves open from the station's [metrology]; `PreparedRecorrect.run` writes the NEW session with
the station's refractive index and dead path (procedures.metrology.recorrect). The original
session is never changed."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from procedures.metrology.air import EQUATIONS  # the equations a request may name (argparse choices)
from station.services.job import JobOutcome, OfflineJob, config_or_load

if TYPE_CHECKING:  # annotations only
    from procedures.metrology.recorrect import RecorrectOptions
    from station.services.config import StationConfig

__all__ = ["EQUATIONS", "PreparedRecorrect", "RecorrectRequest", "prepare_recorrect"]


@dataclass
class RecorrectRequest:
    """Re-correct `session` into `out` (replaced only with `force`). None = as recorded (the air
    values) or the config's [metrology] default (co2_ppm, dead_path_mm, wavelength_nm); `config`:
    the station TOML giving those defaults (None: the built-in config). Air temperature in degC,
    pressure in Pa, humidity in %RH, CO2 in ppm, dead path in mm, wavelength in nm (vacuum)."""

    session: Path
    out: Path
    force: bool = False
    equation: str = "ciddor"
    air_temp_offset_c: float = 0.0
    air_temp_c: float | None = None
    pressure_pa: float | None = None
    humidity_pct: float | None = None
    co2_ppm: float | None = None
    dead_path_mm: float | None = None
    wavelength_nm: float | None = None
    config: Path | None = None


@dataclass
class PreparedRecorrect(OfflineJob):
    """A re-correction that passed the output check; `options` is what the index is computed from."""

    request: RecorrectRequest
    session: Path
    out: Path
    replace: bool  # --force over an existing file other than the source
    options: RecorrectOptions

    def run(self, sinks=(), control=None) -> JobOutcome:
        from procedures.metrology.recorrect import recorrect_session

        if self.replace and self.out.exists():
            self.out.unlink()  # --force: the re-corrected session replaces it
        r = recorrect_session(self.session, self.out, self.options)
        o = self.options
        lines = [
            f"instrument's index: {r.n_instrument[0]:.9f} .. {r.n_instrument[1]:.9f}",
            f"station's index ({o.equation}, {o.wavelength_nm:g} nm): {r.n_station[0]:.9f} .. {r.n_station[1]:.9f}",
            f"dead path {o.dead_path_mm:g} mm; error_um changed by {r.change_um[0]:+.4f} .. {r.change_um[1]:+.4f} um",
            f"written: {self.request.out} (the original {self.request.session} is unchanged; /meta recorrection says what was done)",
        ]
        return JobOutcome("done", outputs=[self.out], lines=lines, data=r)


def prepare_recorrect(request: RecorrectRequest, cfg: StationConfig | None = None) -> PreparedRecorrect:
    """The output check (an existing file refused without force, a name not ending .h5 refused)
    and the defaults from `cfg` (None: load `request.config`)'s [metrology]."""
    from procedures.io.outputs import check_output_file
    from procedures.metrology.recorrect import RecorrectOptions

    r = request
    out = check_output_file(r.out, force=r.force, suffixes=(".h5",))
    cfg = config_or_load(cfg, r.config)
    m = cfg.metrology
    options = RecorrectOptions(
        equation=r.equation,
        wavelength_nm=m.wavelength_nm if r.wavelength_nm is None else r.wavelength_nm,
        co2_ppm=m.co2_ppm if r.co2_ppm is None else r.co2_ppm,
        dead_path_mm=m.dead_path_mm if r.dead_path_mm is None else r.dead_path_mm,
        air_temp_offset_c=r.air_temp_offset_c, air_temp_c=r.air_temp_c,
        pressure_pa=r.pressure_pa, humidity_pct=r.humidity_pct,
    )
    replace = bool(r.force and Path(out).exists() and Path(out).resolve() != Path(r.session).resolve())
    return PreparedRecorrect(r, Path(r.session), Path(r.out), replace, options,
                             lines=[f"re-correct {r.session} ({options.equation}) -> {r.out}"])
