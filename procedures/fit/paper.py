"""The seed paper's leg-error model (Hernandez, Valdez, Sanchez 2014, Algorithm 1, Eqs. 2-7).

Per leg: one error value per target (the paper has one sequence per leg and no direction, so
here the mean over all passes, both directions pooled, at each target), on uniformly spaced
targets x_n = x_start + n * spacing, n = 0..N-1. Algorithm 1:

1-2. f_mean = mean(f); g = f - f_mean
3.   F_k = sum_n g_n exp(-i 2 pi k n / N)                      (Eq. 2, numpy.fft.fft)
4.   A_k = (2 / N) |F_k|                                        (Eq. 3, normalised, see below)
5.   phi_k = arg F_k                                            (Eq. 4)
6.   frequency k (cycles per sweep)                             (Eq. 5)
7.   keep the M largest A_k
model: f(t) = f_mean + sum_kept A_k cos(2 pi k t + phi_k)       (Eq. 6)
with   t = (x - x_start) / (N * spacing)                         (Eq. 7: t = n / N)

Readings of the paper's ambiguities (docs/models.md):
- Amplitude: the paper writes A_k = |F_k|. With numpy's unnormalised DFT the sum in Eq. 6
  reproduces the data only with A_k = 2|F_k|/N for 0 < k < N/2; that is what is stored.
- "First half of the spectrum": k = 1 .. ceil(N/2) - 1 (k = 0 is zero after centring; the
  Nyquist term of an even N is not in Algorithm 1's list and is dropped).
- Algorithm 1 sorts "increasing" but keeps "the greatest amplitudes": the M largest are kept.
- "The most important 100 parameters of amplitudes, frequencies and phases": M = 100 cosine
  terms, each carrying its amplitude, frequency and phase (default `n_params=100`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from procedures.vocabulary import InputError
from procedures.fit.data import LegData
from procedures.fit.model import FitStats, LegFit

DEFAULT_N_PARAMS = 100


class PaperLegFit(LegFit):
    """Sum of cosines over one sweep. Direction is ignored (the paper has none)."""

    method = "paper"

    def __init__(self, leg: int, stroke_mm, target_spacing_mm: float, stats: FitStats, *,
                 x_start_mm: float, spacing_mm: float, n_samples: int, mean_um: float,
                 k: np.ndarray, amplitude_um: np.ndarray, phase_rad: np.ndarray, n_params: int):
        super().__init__(leg, stroke_mm, target_spacing_mm, stats)
        self.x_start_mm = float(x_start_mm)
        self.spacing_mm = float(spacing_mm)
        self.n_samples = int(n_samples)
        self.mean_um = float(mean_um)
        self.k = np.asarray(k, dtype=np.int64)
        self.amplitude_um = np.asarray(amplitude_um, dtype=float)
        self.phase_rad = np.asarray(phase_rad, dtype=float)
        self.n_params = int(n_params)

    def predict_um(self, position_mm, direction=1) -> np.ndarray:
        x = self._clip(position_mm)
        shape = np.broadcast(x, np.asarray(direction)).shape
        t = (x - self.x_start_mm) / (self.n_samples * self.spacing_mm)  # Eq. 7
        t = np.broadcast_to(t, shape)
        out = np.full(shape, self.mean_um)
        for k, a, phi in zip(self.k, self.amplitude_um, self.phase_rad):
            out = out + a * np.cos(2.0 * np.pi * k * t + phi)  # Eq. 6
        return out

    def describe(self) -> str:
        available = (self.n_samples + 1) // 2 - 1
        return f"mean + {self.k.size} of {available} cosines, N = {self.n_samples} targets at {self.spacing_mm:g} mm"

    def model_json(self) -> dict[str, Any]:
        return {
            "x_start_mm": self.x_start_mm,
            "spacing_mm": self.spacing_mm,
            "n_samples": self.n_samples,
            "n_params": self.n_params,
            "mean_um": self.mean_um,
            "k": [int(v) for v in self.k],
            "amplitude_um": [float(v) for v in self.amplitude_um],
            "phase_rad": [float(v) for v in self.phase_rad],
        }


def uniform_grid(data: LegData, where: str) -> tuple[np.ndarray, float]:
    """The distinct targets and their spacing; `InputError` unless they are uniformly spaced."""
    targets = data.targets_mm()
    if targets.size < 3:
        raise InputError(f"{where}: the paper's method needs at least 3 targets, the leg has {targets.size}")
    steps = np.diff(targets)
    spacing = float(np.median(steps))
    tol = max(1e-6, 1e-4 * spacing)
    bad = np.flatnonzero(np.abs(steps - spacing) > tol)
    if bad.size:
        i = int(bad[0])
        raise InputError(
            f"{where}: the paper's method needs uniformly spaced targets (Eq. 7 maps a position to a "
            f"sample index), but the targets are {steps.min():.4g} to {steps.max():.4g} mm apart (first "
            f"irregular step: {targets[i]:.4f} -> {targets[i + 1]:.4f} mm); use --method default, "
            "which fits at the real positions"
        )
    return targets, spacing


def paper_coefficients(f_um: np.ndarray, n_params: int) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Algorithm 1 on one sequence: (mean, k, amplitude, phase) of the `n_params` largest
    terms, amplitudes normalised so that Eq. 6 reproduces the sequence at t = n/N."""
    n = f_um.size
    f_mean = float(np.mean(f_um))
    spectrum = np.fft.fft(f_um - f_mean)
    k_all = np.arange(1, (n + 1) // 2)  # 0 < k < N/2
    amp = 2.0 * np.abs(spectrum[k_all]) / n
    phase = np.angle(spectrum[k_all])
    # stable sort on -amplitude: ties keep the lower frequency first (deterministic)
    order = np.argsort(-amp, kind="stable")[: max(0, int(n_params))]
    return f_mean, k_all[order], amp[order], phase[order]


def fit_paper_leg(data: LegData, n_params: int = DEFAULT_N_PARAMS, stats: FitStats | None = None,
                  where: str = "") -> PaperLegFit:
    """Algorithm 1 on one leg (see the module docstring). `InputError` for irregular spacing."""
    where = where or f"leg {data.leg}"
    if n_params < 1:
        raise InputError(f"{where}: the number of cosine terms must be >= 1, got {n_params}")
    targets, spacing = uniform_grid(data, where)
    idx = np.searchsorted(targets, data.position_mm)
    counts = np.bincount(idx, minlength=targets.size)
    f_um = np.bincount(idx, weights=data.error_um, minlength=targets.size) / counts
    f_mean, k, amp, phase = paper_coefficients(f_um, n_params)
    if stats is None:
        stats = FitStats(data.n_points, data.n_passes, data.n_cycles, data.dropped, 0, None, None, None,
                         float(np.ptp(data.error_um)), None)
    return PaperLegFit(
        data.leg, (float(targets[0]), float(targets[-1])), spacing, stats,
        x_start_mm=float(targets[0]), spacing_mm=spacing, n_samples=targets.size, mean_um=f_mean,
        k=k, amplitude_um=amp, phase_rad=phase, n_params=n_params,
    )


def paper_from_json(leg: int, stroke_mm, target_spacing_mm: float, stats: FitStats, m: dict[str, Any]) -> PaperLegFit:
    return PaperLegFit(
        leg, stroke_mm, target_spacing_mm, stats,
        x_start_mm=m["x_start_mm"], spacing_mm=m["spacing_mm"], n_samples=m["n_samples"],
        mean_um=m["mean_um"], k=np.array(m["k"], dtype=np.int64), amplitude_um=np.array(m["amplitude_um"], dtype=float),
        phase_rad=np.array(m["phase_rad"], dtype=float), n_params=m["n_params"],
    )
