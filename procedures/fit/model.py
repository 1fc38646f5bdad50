"""The fitted leg-error model: per-leg fits behind one `predict_um`, plus fit statistics.

Conventions: positions in mm (leg coordinates, mid-stroke = 0); predicted error in um, measured
minus commanded (positive = the leg ends up longer than commanded); direction +1 = approaching
while the position increases. A controller *subtracts* the prediction from the command.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from procedures.fit.figures import reduction_pct

FORMAT = "station-leg-error-model"
VERSION = 1
METHODS = ("default", "paper")


@dataclass(frozen=True)
class FitStats:
    """How well a leg's model does (um). Held-out figures come from cross-validation over whole
    cycles (docs/models.md): a model fitted without a cycle is scored on that cycle. Names and
    definitions of every figure: docs/figures.md.

    `noise_floor_um` / `within_pass_um`: procedures.fit.noise. `heldout_rms_um`: RMS of the
    held-out residuals (error minus prediction); `range_before_um`: max - min of the measured
    errors; `heldout_range_um`: max - min of the held-out residuals. Held-out figures are None
    when the leg has fewer than two cycles. (Model files written before the rename call
    `heldout_range_um` `range_after_um`; `load_model` reads both.)
    """

    n_points: int
    n_passes: int
    n_cycles: int
    dropped: int
    folds: int
    noise_floor_um: float | None
    within_pass_um: float | None
    heldout_rms_um: float | None
    range_before_um: float
    heldout_range_um: float | None
    note: str = ""

    @property
    def heldout_ratio(self) -> float | None:
        """Held-out RMS divided by the noise floor (1.0 = as good as repeat passes allow)."""
        if self.heldout_rms_um is None or not self.noise_floor_um:
            return None
        return self.heldout_rms_um / self.noise_floor_um

    @property
    def ideal_heldout_ratio(self) -> float | None:
        """The held-out ratio a perfect static model would score in this cross-validation: a
        model fitted on n_train cycles misses the held-out cycle's offset by the offset scatter /
        sqrt(n_train), so ratio^2 = 1 + rho / n_train, rho = share of the scatter that is shared
        within a pass (1 - within_pass^2 / noise_floor^2). See docs/models.md."""
        if not self.noise_floor_um or self.within_pass_um is None or self.folds < 2 or self.n_cycles < 2:
            return None
        rho = max(0.0, 1.0 - (self.within_pass_um / self.noise_floor_um) ** 2)
        n_train = self.n_cycles * (self.folds - 1) / self.folds
        return float(np.sqrt(1.0 + rho / n_train))

    @property
    def heldout_range_reduction_pct(self) -> float | None:
        """100 (1 - held-out range / range before)."""
        return reduction_pct(self.range_before_um, self.heldout_range_um)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


class LegFit:
    """One leg's fitted model. Subclasses: `BidirectionalLegFit` (default), `PaperLegFit`."""

    method: str = ""

    def __init__(self, leg: int, stroke_mm: tuple[float, float], target_spacing_mm: float, stats: FitStats):
        self.leg = int(leg)
        self.stroke_mm = (float(stroke_mm[0]), float(stroke_mm[1]))
        self.target_spacing_mm = float(target_spacing_mm)
        self.stats = stats

    # -- figures ----------------------------------------------------------------------------
    @property
    def heldout_rms_um(self) -> float | None:
        return self.stats.heldout_rms_um

    @property
    def noise_floor_um(self) -> float | None:
        return self.stats.noise_floor_um

    # -- prediction ---------------------------------------------------------------------------
    def _clip(self, position_mm) -> np.ndarray:
        # hold the end values outside the recorded stroke: no extrapolation
        return np.clip(np.asarray(position_mm, dtype=float), self.stroke_mm[0], self.stroke_mm[1])

    def predict_um(self, position_mm, direction=1) -> np.ndarray:
        """Predicted error (measured minus commanded, um) at `position_mm` approached in
        `direction` (+1/-1, broadcast against the positions)."""
        raise NotImplementedError

    def describe(self) -> str:
        """One line: the terms the model uses."""
        raise NotImplementedError

    def model_json(self) -> dict[str, Any]:
        raise NotImplementedError

    def to_json(self) -> dict[str, Any]:
        return {
            "stroke_mm": [self.stroke_mm[0], self.stroke_mm[1]],
            "target_spacing_mm": self.target_spacing_mm,
            "stats": self.stats.to_json(),
            "model": self.model_json(),
        }


class LegErrorModel:
    """Fitted models of several legs.

    `legs` maps leg number -> `LegFit` (iterate it for the leg numbers; each `LegFit` has
    `.stroke_mm` (min, max), `.heldout_rms_um`, `.noise_floor_um`, `.stats`).
    `source` names the recording it came from: {"path": ..., "sha256": ...}.
    """

    def __init__(self, method: str, legs: Mapping[int, LegFit], source: Mapping[str, str] | None = None,
                 options: Mapping[str, Any] | None = None, created_utc: str = "",
                 identity: Mapping[str, Any] | None = None):
        self.method = method
        self.legs: Mapping[int, LegFit] = MappingProxyType({int(k): legs[k] for k in sorted(legs)})
        self.source = dict(source or {"path": "", "sha256": ""})
        self.options = dict(options or {})
        self.created_utc = created_utc
        # station, operator, software version, per leg serial/part number/type of the session it
        # was fitted to (procedures.io.recording.identity.model_identity); {} in older model files
        self.identity = dict(identity or {})
        # read from a file: "verified" (its integrity record matched) or "unverified" (it had none;
        # procedures/io/integrity.py); "" for a model made in memory
        self.integrity = ""

    def leg(self, leg: int) -> LegFit:
        try:
            return self.legs[int(leg)]
        except KeyError:
            raise KeyError(f"the model has no leg {leg} (it has legs {list(self.legs)})") from None

    def predict_um(self, leg: int, position_mm, direction=1) -> np.ndarray:
        """Predicted error of `leg` (um, measured minus commanded) at `position_mm` (mm)
        approached in `direction` (+1/-1). Outside the recorded stroke the end value is held."""
        return self.leg(leg).predict_um(position_mm, direction)
