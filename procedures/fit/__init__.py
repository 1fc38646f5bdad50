"""Leg-error models: the seed paper's Fourier model and the default bidirectional model.

    fit(points, method="default"|"paper", **opts) -> LegErrorModel
    save_model(model, path, source_path, source_sha256) / load_model(path) -> LegErrorModel

See docs/models.md for the methods, their assumptions and the statistics they report.
"""

from procedures.fit.fitting import fit, fit_leg
from procedures.fit.model import FitStats, LegErrorModel, LegFit
from procedures.fit.model_io import load_model, model_to_json, save_model

__all__ = ["fit", "fit_leg", "FitStats", "LegErrorModel", "LegFit", "load_model", "model_to_json", "save_model"]
