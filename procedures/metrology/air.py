"""Refractive index of air for a laser's vacuum wavelength: the Ciddor (1996) equation and the
modified Edlen equation (Edlen 1966 as updated by Birch and Downs 1993/1994, with NIST's
modification of the water-vapour term), both as NIST's Engineering Metrology Toolbox states them
(J. A. Stone, J. H. Zimmerman, "Index of Refraction of Air", emtoolbox.nist.gov/Wavelength/
Documentation.asp, Appendix A). Written from those equations; no code copied.

Inputs, units in the names: `wavelength_nm` vacuum wavelength, `temp_c` air temperature,
`pressure_pa` total air pressure, `humidity_pct` relative humidity (0..100 %RH, over water above
0 degC and over ice below), `co2_ppm` CO2 mole fraction in umol/mol. All accept numpy arrays
(broadcast). NIST gives the uncertainty of either equation as about 2e-8 (k = 2) within
300..1700 nm, -40..100 degC (Ciddor) / 0..40 degC (Edlen), 10..140 kPa, 0..100 %RH.

Sensitivities near 20 degC, 101.325 kPa, 50 %RH, 633 nm: dn/dT = -0.93 ppm/K,
dn/dp = +0.0027 ppm/Pa, dn/dRH = -0.0085 ppm/%RH, dn/dCO2 = +1.4e-4 ppm/ppm.
"""

from __future__ import annotations

import numpy as np

EQUATIONS = ("ciddor", "edlen")

# -- saturation vapour pressure (NIST A-I): IAPWS over water, and over ice below 0 degC --------
_K = (1.16705214528e3, -7.24213167032e5, -1.70738469401e1, 1.20208247025e4, -3.23255503223e6,
      1.49151086135e1, -4.82326573616e3, 4.05113405421e5, -2.38555575678e-1, 6.50175348448e2)


def saturation_vapour_pressure_pa(temp_c):
    """Saturation vapour pressure of water, Pa: over liquid water at temp_c >= 0 (IAPWS 1997),
    over ice below (IAPWS sublimation), as NIST A-I."""
    t = np.asarray(temp_c, dtype=float)
    T = t + 273.15
    omega = T + _K[8] / (T - _K[9])
    a = omega ** 2 + _K[0] * omega + _K[1]
    b = _K[2] * omega ** 2 + _K[3] * omega + _K[4]
    c = _K[5] * omega ** 2 + _K[6] * omega + _K[7]
    x = -b + np.sqrt(b * b - 4.0 * a * c)
    water = 1e6 * (2.0 * c / x) ** 4
    theta = T / 273.16
    y = -13.928169 * (1.0 - theta ** -1.5) + 34.7078238 * (1.0 - theta ** -1.25)
    ice = 611.657 * np.exp(y)
    return np.where(t >= 0.0, water, ice)


def _sigma2(wavelength_nm):
    """Wavenumber squared, um^-2."""
    return (1000.0 / np.asarray(wavelength_nm, dtype=float)) ** 2


# -- Ciddor (NIST A-III) -----------------------------------------------------------------------
_W = (295.235, 2.6422, -0.032380, 0.004028)  # water vapour dispersion, um^-2 powers
_K0, _K1, _K2, _K3 = 238.0185, 5792105.0, 57.362, 167917.0  # dry-air dispersion
_A0, _A1, _A2 = 1.58123e-6, -2.9331e-8, 1.1043e-10  # compressibility (BIPM 1981/91)
_B0, _B1 = 5.707e-6, -2.051e-8
_C0, _C1 = 1.9898e-4, -2.376e-6
_D, _E = 1.83e-11, -0.765e-8
_P_R1, _T_R1 = 101325.0, 288.15  # standard dry air: 15 degC, 101 325 Pa
_Z_A = 0.9995922115  # its compressibility
_RHO_VS = 0.00985938  # kg/m^3, standard water vapour: 20 degC, 1333 Pa
_R = 8.314472  # J/(mol K)
_M_V = 0.018015  # kg/mol, water
# enhancement factor of water vapour in air, f = alpha + beta p + gamma t^2
_F_ALPHA, _F_BETA, _F_GAMMA = 1.00062, 3.14e-8, 5.6e-7


def _compressibility(T, t, p, xv):
    return (1.0 - (p / T) * (_A0 + _A1 * t + _A2 * t * t + (_B0 + _B1 * t) * xv + (_C0 + _C1 * t) * xv * xv)
            + (p / T) ** 2 * (_D + _E * xv * xv))


def ciddor(wavelength_nm, temp_c, pressure_pa, humidity_pct, co2_ppm=450.0):
    """Phase refractive index of moist air by Ciddor (1996), as NIST A-III."""
    s = _sigma2(wavelength_nm)
    t = np.asarray(temp_c, dtype=float)
    p = np.asarray(pressure_pa, dtype=float)
    T = t + 273.15
    x_co2 = np.asarray(co2_ppm, dtype=float)
    # mole fraction of water vapour from relative humidity (NIST A-II)
    f = _F_ALPHA + _F_BETA * p + _F_GAMMA * t * t
    xv = np.asarray(humidity_pct, dtype=float) / 100.0 * f * saturation_vapour_pressure_pa(t) / p
    r_as = 1e-8 * (_K1 / (_K0 - s) + _K3 / (_K2 - s))
    r_vs = 1.022e-8 * (_W[0] + _W[1] * s + _W[2] * s * s + _W[3] * s ** 3)
    m_a = 0.0289635 + 1.2011e-8 * (x_co2 - 400.0)  # molar mass of dry air with CO2
    r_axs = r_as * (1.0 + 5.34e-7 * (x_co2 - 450.0))
    z_m = _compressibility(T, t, p, xv)
    rho_axs = _P_R1 * m_a / (_Z_A * _R * _T_R1)
    rho_v = xv * p * _M_V / (z_m * _R * T)
    rho_a = (1.0 - xv) * p * m_a / (z_m * _R * T)
    return 1.0 + (rho_a / rho_axs) * r_axs + (rho_v / _RHO_VS) * r_vs


# -- modified Edlen (NIST A-IV: Birch and Downs, NIST's water term) ----------------------------
def edlen(wavelength_nm, temp_c, pressure_pa, humidity_pct, co2_ppm=450.0):
    """Refractive index of moist air by the modified Edlen equation, as NIST A-IV.

    NIST's equation is for 450 ppm CO2 (Birch and Downs' standard air) and takes no CO2 input;
    for another `co2_ppm` the dry-air refractivity is scaled by 1 + 5.34e-7 (co2_ppm - 450), the
    CO2 factor of Ciddor's equation (Edlen's own 1966 factor is 0.540 per unit mole fraction),
    so at 450 ppm this is NIST's equation exactly."""
    s = _sigma2(wavelength_nm)
    t = np.asarray(temp_c, dtype=float)
    p = np.asarray(pressure_pa, dtype=float)
    pv = np.asarray(humidity_pct, dtype=float) / 100.0 * saturation_vapour_pressure_pa(t)
    ns_1 = 1e-8 * (8342.54 + 2406147.0 / (130.0 - s) + 15998.0 / (38.9 - s))
    ns_1 = ns_1 * (1.0 + 5.34e-7 * (np.asarray(co2_ppm, dtype=float) - 450.0))
    x = (1.0 + 1e-8 * (0.601 - 0.00972 * t) * p) / (1.0 + 0.003661 * t)
    n_tp = 1.0 + p * ns_1 * x / 96095.43
    return n_tp - 1e-10 * (292.75 / (t + 273.15)) * (3.7345 - 0.0401 * s) * pv


def refractive_index(equation: str, wavelength_nm, temp_c, pressure_pa, humidity_pct, co2_ppm=450.0):
    """n by the named equation ("ciddor" or "edlen")."""
    if equation == "ciddor":
        return ciddor(wavelength_nm, temp_c, pressure_pa, humidity_pct, co2_ppm)
    if equation == "edlen":
        return edlen(wavelength_nm, temp_c, pressure_pa, humidity_pct, co2_ppm)
    raise ValueError(f"unknown refractive-index equation {equation!r}; known: {', '.join(EQUATIONS)}")
