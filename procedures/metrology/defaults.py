"""One home for the measurement chain's defaults: what a station assumes when its config gives no
[metrology] or [legs] key (station.services.config), and what the metrology modules take when a session
recorded none. Standard uncertainties (k = 1) are named `*_U_*`; the laser's stated accuracy is
expanded (k = 2), as laser makers state it."""

from __future__ import annotations

REFERENCE_TEMP_C = 20.0  # ISO 1 reference temperature of lengths
WAVELENGTH_NM = 632.991  # vacuum wavelength of a HeNe laser
CO2_PPM = 450.0  # CO2 mole fraction of the air when not measured
DEAD_PATH_MM = 0.0  # beam path between the laser and the interferometer's zero
LASER_ACCURACY_PPM = 0.5  # stated accuracy, k = 2
LASER_RESOLUTION_NM = 1.0  # display/count resolution
AIR_TEMP_U_C = 0.1  # standard uncertainty of the air temperature sensor
PRESSURE_U_PA = 50.0  # of the pressure sensor
HUMIDITY_U_PCT = 3.0  # of the humidity sensor, %RH
MATERIAL_TEMP_U_C = 0.1  # of the material temperature sensor
MISALIGNMENT_MM = 0.0  # lateral beam offset over the whole stroke (cosine error)
ABBE_OFFSET_MM = 0.0  # distance between the beam and the leg's axis
ABBE_ANGLE_U_URAD = 0.0  # standard uncertainty of the pitch/yaw angle over the stroke

# a leg's material: steel, fixed at 0 mm
EXPANSION_UM_M_K = 11.5  # linear expansion coefficient, um per metre per kelvin
EXPANSION_U_UM_M_K = 1.0  # its standard uncertainty
FIXED_POINT_MM = 0.0  # where the leg's thermal expansion is zero, in target_mm
