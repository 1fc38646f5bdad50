"""The job of `station recordings` (issue 32 part 1, one shape for every job): make the sample
sessions of recordings/ on the simulated rig (station/services/samples.py says what each is),
under temporary names renamed at the end, so a failed run leaves the old samples."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from procedures.vocabulary import InputError
from station.services.job import JobOutcome
from station.services.samples import FILES, SAMPLES


@dataclass
class SamplesRequest:
    """Make the samples `only` (None: all of SAMPLES) in the folder `out`."""

    out: Path = Path("recordings")
    only: tuple[str, ...] | None = None


@dataclass
class PreparedSamples:
    wanted: tuple[str, ...]
    out_dir: Path
    final: dict[str, Path]
    say: Callable[[str], None]  # told each sample as it is made
    needs_rig: bool = False  # the simulated rig of its own, on loopback: not the station's drives
    question: str | None = None
    lines: list[str] = field(default_factory=list)

    def run(self, sinks=(), control=None) -> JobOutcome:
        from procedures.io.atomic_outputs import atomic_paths

        self.out_dir.mkdir(parents=True, exist_ok=True)
        # made under temporary names and renamed at the end: a failed run leaves the old samples
        with atomic_paths(self.final.values(), suffix=".h5", exists=False) as temps:  # the sweep creates them
            self._make({name: temps[path] for name, path in self.final.items()})
        lines = [f"  {path}: {path.stat().st_size / 1e6:.2f} MB" for path in self.final.values()]
        return JobOutcome("done", outputs=list(self.final.values()), lines=lines)

    def _make(self, targets: dict[str, Path]) -> None:
        from station.services.samples import make_calibration, make_fault, make_verification, open_sample_rig, \
            sample_config

        cfg, wanted, say = sample_config(), self.wanted, self.say
        if "calibration" in wanted:
            with open_sample_rig() as rig:
                res = make_calibration(rig, targets["calibration"], cfg)
                say(f"{FILES['calibration']}: {res.outcome}, {res.points} points")
                if "verification" in wanted:
                    for line in make_verification(rig, targets["calibration"], targets["verification"], cfg):
                        say(f"  {line}")
                    say(f"{FILES['verification']}: written")
        if "fault" in wanted:
            with open_sample_rig() as rig:
                res = make_fault(rig, targets["fault"], cfg)
                say(f"{FILES['fault']}: {res.outcome}, {res.points} points ({res.reason})")


def prepare_samples(request: SamplesRequest, say: Callable[[str], None] = lambda line: None) -> PreparedSamples:
    """Refuse an unknown sample, or the verification without the calibration it is fitted to."""
    wanted = SAMPLES if request.only is None else tuple(request.only)
    unknown = [w for w in wanted if w not in SAMPLES]
    if unknown:
        raise InputError(f"--only: unknown sample(s) {unknown}; choose from {', '.join(SAMPLES)}")
    if "verification" in wanted and "calibration" not in wanted:
        raise InputError("--only verification needs calibration too (the tables are fitted to it on the same rig)")
    out_dir = Path(request.out)
    final = {name: out_dir / FILES[name] for name in wanted}
    return PreparedSamples(tuple(wanted), out_dir, final, say, lines=[f"samples {', '.join(wanted)} -> {out_dir}"])
