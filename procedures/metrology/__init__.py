"""The measurement chain: air refractive index, re-correction of the laser's air compensation,
normalisation of lengths to the 20 degC reference temperature (docs/metrology.md), values that
look like a unit slip (plausibility)."""
