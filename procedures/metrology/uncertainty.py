"""Measurement uncertainty of the ISO 230-2 values and of compensation table entries, in the
manner of ISO/TR 230-9 (GUM, linear propagation, coverage factor k = 2). docs/uncertainty.md.

The measurement model of one reading at target P (mm from the leg's mid-stroke reference,
where the laser is zeroed), micrometres, error = measured - target (the project's sign):

    x = x_true + 1e-3 * P * (eps_laser + eps_air + eps_cos)                  length-proportional
          - 1e-3 * [(alpha + d_alpha) * (T + d_T - T_ref) - alpha * (T - T_ref)] * (P - P_fixed)
          + abbe + dead_path + resolution + noise

eps_* in ppm (1 ppm = 1e-3 um per mm): the laser's own scale error, the refractive-index error
from the air sensors' errors (eps_air = -(S_T dT_air + S_p dp + S_h dh): n too small makes the
laser read long), the cosine error of a misaligned beam; the normalisation to T_ref (NDE) with
the material sensor's error d_T and the coefficient's error d_alpha; the Abbe error
h * theta(P); the dead path d changing with the air during the test; the resolution; the
repeatability seen in the data.

Every ISO 230-2 value is, at the extremes the data show, a linear form of target means and
estimators s (see `_forms`): E = x_a - x_b, M = (x_a(up) + x_a(down))/2 - (...)_b,
A = x_a + 2 s_a - x_b + 2 s_b, B = |x_i(up) - x_i(down)|, R = 4 s_i or 2 s_up + 2 s_down + |B_i|.
Its standard uncertainty is the root sum of squares of the contributions c_k * u(x_k), where:
- the length-proportional and NDE terms are the SAME at every target of a session (one
  instrument, one set of sensors): fully correlated, so they enter through the span between the
  extremes (sum of coef * P), not as independent terms; B (one target) has none;
- the means and estimators at different targets are independent (different approaches):
  u(mean) = s / sqrt(n), u(s) = s / sqrt(2 (n - 1));
- the Abbe angle at different positions is independent (none for B: same position), the dead
  path's drift and the resolution at different means are independent.
The extremes (which targets set max and min) are taken as found: the linearisation of GUM. When
another target comes within the value's u of an extreme, the budget notes it (the max of several
nearly equal means spreads less than one mean: U is then on the safe side).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Iterable

import numpy as np

from procedures.metrology import defaults as D

K_COVERAGE = 2.0
SQRT3 = math.sqrt(3.0)
SQRT12 = math.sqrt(12.0)
TARGET_TOLERANCE_MM = 0.001  # as procedures.reporting.iso230: targets closer than this are one position

# Sensitivities of the air refractive index near 20 degC, 1013.25 hPa, 50 %RH, 633 nm (Ciddor
# 1996; docs/uncertainty.md), ppm of n per unit; used when procedures.metrology.air is missing.
AIR_SENSITIVITY_FALLBACK = {"temp_ppm_per_k": -0.95, "pressure_ppm_per_pa": 0.0027,
                            "humidity_ppm_per_pct": -0.0085}


@dataclass(frozen=True)
class UncertaintyInputs:
    """The measurement chain's uncertainties (names and units as station.services.config's [metrology] and
    [legs]). `*_u_*` are standard uncertainties (k = 1); `laser_accuracy_ppm` is the laser's
    stated accuracy, expanded (k = 2). Defaults: the station's config defaults."""

    laser_accuracy_ppm: float = D.LASER_ACCURACY_PPM
    laser_resolution_nm: float = D.LASER_RESOLUTION_NM
    wavelength_nm: float = D.WAVELENGTH_NM
    co2_ppm: float = D.CO2_PPM
    reference_temp_c: float = D.REFERENCE_TEMP_C
    dead_path_mm: float = D.DEAD_PATH_MM
    air_temp_u_c: float = D.AIR_TEMP_U_C
    pressure_u_pa: float = D.PRESSURE_U_PA
    humidity_u_pct: float = D.HUMIDITY_U_PCT
    material_temp_u_c: float = D.MATERIAL_TEMP_U_C
    misalignment_mm: float = D.MISALIGNMENT_MM  # lateral beam walk-off observed over the stroke
    abbe_offset_mm: float = D.ABBE_OFFSET_MM
    abbe_angle_u_urad: float = D.ABBE_ANGLE_U_URAD
    expansion_um_m_k: float = D.EXPANSION_UM_M_K
    expansion_u_um_m_k: float = D.EXPANSION_U_UM_M_K
    fixed_point_mm: float = D.FIXED_POINT_MM

    @classmethod
    def from_config(cls, cfg: Any, leg: int) -> "UncertaintyInputs":
        """From a station.services.config.StationConfig (its [metrology] and the leg's [legs] material)."""
        m = getattr(cfg, "metrology", None)
        mat = cfg.material_of(leg) if hasattr(cfg, "material_of") else None
        return cls.from_dicts(asdict(m) if m is not None else {}, asdict(mat) if mat is not None else {})

    @classmethod
    def from_record(cls, station_config: dict, leg: int) -> "UncertaintyInputs":
        """From a session's recorded station_config (its `metrology` and `leg_materials`, or
        StationConfig.to_dict's `legs`/`leg_overrides`): a session made before [metrology] existed
        gets the defaults."""
        per_leg = station_config.get("leg_materials") or station_config.get("leg_overrides") or {}
        mat = per_leg.get(str(leg)) or station_config.get("legs") or {}
        return cls.from_dicts(station_config.get("metrology") or {}, mat)

    @classmethod
    def from_dicts(cls, metrology: dict, material: dict) -> "UncertaintyInputs":
        names = set(cls.__dataclass_fields__)
        values = {k: float(v) for k, v in {**metrology, **material}.items()
                  if k in names and isinstance(v, (int, float)) and not isinstance(v, bool)}
        return cls(**values)


@dataclass(frozen=True)
class Contribution:
    """One line of a budget: input quantity `quantity` (in `unit`) with standard uncertainty
    `u_input`, sensitivity coefficient `sensitivity` (um per `unit`), contribution
    |sensitivity| * u_input (um). `distribution` says how u_input was obtained."""

    source: str  # laser, air temperature, ..., repeatability
    quantity: str
    unit: str
    u_input: float
    sensitivity: float
    distribution: str

    @property
    def u_um(self) -> float:
        return abs(self.sensitivity) * self.u_input


@dataclass(frozen=True)
class ValueBudget:
    """Uncertainty budget of one ISO 230-2 value (um). `formed` says which targets set it and how
    its uncertainty is formed; `notes` flag where the linearisation is weak."""

    name: str
    value_um: float
    contributions: tuple[Contribution, ...]
    formed: str
    notes: tuple[str, ...] = ()
    k: float = K_COVERAGE

    @property
    def u_um(self) -> float:
        return math.sqrt(sum(c.u_um ** 2 for c in self.contributions))

    @property
    def U_um(self) -> float:
        return self.k * self.u_um

    def dominant(self) -> Contribution | None:
        return max(self.contributions, key=lambda c: c.u_um) if self.contributions else None

    def to_json(self) -> dict[str, Any]:
        return {"value_um": self.value_um, "u_um": self.u_um, "U_um": self.U_um, "k": self.k,
                "formed": self.formed, "notes": list(self.notes),
                "contributions": [{"source": c.source, "quantity": c.quantity, "unit": c.unit,
                                   "u_input": c.u_input, "sensitivity_um_per_unit": c.sensitivity,
                                   "distribution": c.distribution, "u_um": c.u_um} for c in self.contributions]}


# -- the air -------------------------------------------------------------------------------------------

def air_sensitivities(temp_c: float = 20.0, pressure_pa: float = 101325.0, humidity_pct: float = 50.0,
                      co2_ppm: float = 450.0, wavelength_nm: float = 632.991) -> dict[str, float]:
    """d n / d(temperature, pressure, humidity) in ppm per K, Pa, %RH at the given air, by central
    differences of the Ciddor equation (procedures.metrology.air) when it is available, else the
    published values near standard air (AIR_SENSITIVITY_FALLBACK)."""
    n = _ciddor()
    if n is None:
        return dict(AIR_SENSITIVITY_FALLBACK, equation="fallback (published sensitivities near standard air)")

    def d(dt=0.0, dp=0.0, dh=0.0) -> float:
        return n(wavelength_nm, temp_c + dt, pressure_pa + dp, humidity_pct + dh, co2_ppm)

    ht, hp, hh = 0.5, 50.0, 2.0
    return {"temp_ppm_per_k": 1e6 * (d(dt=ht) - d(dt=-ht)) / (2 * ht),
            "pressure_ppm_per_pa": 1e6 * (d(dp=hp) - d(dp=-hp)) / (2 * hp),
            "humidity_ppm_per_pct": 1e6 * (d(dh=hh) - d(dh=-hh)) / (2 * hh),
            "equation": "Ciddor (1996), numerical derivatives"}


def _ciddor():
    """n(wavelength_nm, temp_c, pressure_pa, humidity_pct, co2_ppm) from procedures.metrology.air,
    or None while that module is not there (or names its function otherwise)."""
    try:
        from procedures.metrology import air  # noqa: PLC0415 (optional, written alongside)
    except ImportError:
        return None
    fn = getattr(air, "ciddor_n", None) or getattr(air, "refractive_index_ciddor", None) or getattr(air, "ciddor", None)
    if fn is None:
        return None

    def n(wl, t, p, h, co2):
        return float(fn(wavelength_nm=wl, temp_c=t, pressure_pa=p, humidity_pct=h, co2_ppm=co2))

    try:
        n(632.991, 20.0, 101325.0, 50.0, 450.0)
    except TypeError:
        return None
    return n


# -- what a session says about its environment ------------------------------------------------------

@dataclass(frozen=True)
class Environment:
    """Recorded environment of one leg's points (None: not measured)."""

    air_temp_c: tuple[float, float] | None
    pressure_pa: tuple[float, float] | None
    humidity_pct: tuple[float, float] | None
    material_temp_c: tuple[float, float] | None
    material_mean_c: float | None

    @staticmethod
    def of(points: np.ndarray) -> "Environment":
        def rng(name, scale=1.0):
            if points.dtype.names is None or name not in points.dtype.names:
                return None
            v = points[name][np.isfinite(points[name])] * scale
            return (float(v.min()), float(v.max())) if v.size else None

        mt = rng("material_temp_c")
        mean = None
        if mt is not None:
            v = points["material_temp_c"]
            mean = float(np.mean(v[np.isfinite(v)]))
        return Environment(rng("air_temp_c"), rng("air_pressure_hpa", 100.0), rng("humidity_pct"), mt, mean)

    dn_range_ppm: float = 0.0  # how far the air's refractive index moved during the test

    def with_dn_range(self, points: np.ndarray, sens: dict[str, float]) -> "Environment":
        """The range (max - min, ppm) of n over the points, linearised about the session's air;
        a quantity not recorded counts as constant."""
        dn = np.zeros(len(points))
        for name, scale, key in (("air_temp_c", 1.0, "temp_ppm_per_k"), ("air_pressure_hpa", 100.0, "pressure_ppm_per_pa"),
                                 ("humidity_pct", 1.0, "humidity_ppm_per_pct")):
            if points.dtype.names is not None and name in points.dtype.names:
                v = points[name] * scale
                ok = np.isfinite(v)
                if ok.any():
                    dn += np.where(ok, v - np.mean(v[ok]), 0.0) * sens[key]
        return replace(self, dn_range_ppm=float(np.ptp(dn)) if dn.size else 0.0)


# -- the budget ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Term:
    """coef * (mean or s) of one target and direction, in a value's linear form."""

    coef: float
    kind: str  # "mean" or "s"
    direction: int  # +1 up, -1 down
    target_mm: float
    mean_um: float
    s_um: float
    n: int
    material_dt_k: float  # mean material temperature at this target minus T_ref (0 if unknown)


def _stats_terms(stats, direction: int, temps: dict) -> list[dict]:
    return [dict(direction=direction, target_mm=t.target_mm, mean_um=t.mean_um, s_um=t.s_um or 0.0, n=t.n,
                 material_dt_k=temps.get((direction, round(t.target_mm, 3)), 0.0)) for t in stats]


def _target_temps(points: np.ndarray, ref_c: float) -> dict:
    """(direction, target rounded to um) -> mean material temperature - ref (K), where recorded."""
    out: dict = {}
    if points.dtype.names is None or "material_temp_c" not in points.dtype.names:
        return out
    for d in (1, -1):
        sel = points[points["direction"] == d]
        for t in np.unique(np.round(sel["target_mm"], 3)):
            v = sel["material_temp_c"][np.abs(sel["target_mm"] - t) <= TARGET_TOLERANCE_MM]
            v = v[np.isfinite(v)]
            if v.size:
                out[(d, float(t))] = float(v.mean()) - ref_c
    return out


def _word(d: int) -> str:
    return "up" if d > 0 else "down"


def _at(t: dict) -> str:
    return f"{t['target_mm']:+.4g} mm {_word(t['direction'])}"


def _term(coef: float, kind: str, t: dict) -> Term:
    return Term(coef, kind, **t)


def _forms(r, temps: dict) -> dict[str, tuple[float, list[Term], str, list[str]]]:
    """Each ISO value of `r` (procedures.reporting.iso230.LegIso230) as (value, linear form, how, notes)."""
    up = _stats_terms(r.up, 1, temps)
    down = _stats_terms(r.down, -1, temps)
    out: dict = {}

    def near(values: list[float], best: int, sign: int, u_scale: float) -> int:
        """How many other candidates lie within u_scale of the extreme (ties weaken linearisation)."""
        return sum(1 for i, v in enumerate(values) if i != best and sign * (values[best] - v) < u_scale)

    def range_form(name, cands, plus2s: bool):
        if len(cands) < 2:
            return
        hi = [c["mean_um"] + (2 * c["s_um"] if plus2s else 0) for c in cands]
        lo = [c["mean_um"] - (2 * c["s_um"] if plus2s else 0) for c in cands]
        a, b = int(np.argmax(hi)), int(np.argmin(lo))
        terms = [_term(1.0, "mean", cands[a]), _term(-1.0, "mean", cands[b])]
        how = f"{name} = x({_at(cands[a])}) - x({_at(cands[b])})"
        if plus2s:
            terms += [_term(2.0, "s", cands[a]), _term(2.0, "s", cands[b])]
            how = f"{name} = [x + 2s]({_at(cands[a])}) - [x - 2s]({_at(cands[b])})"
        u_ref = max(math.hypot(cands[a]["s_um"], cands[b]["s_um"]) / math.sqrt(min(cands[a]["n"], cands[b]["n"])), 1e-12)
        ties = near(hi, a, 1, u_ref) + near(lo, b, -1, u_ref)
        notes = [f"{ties} other target(s) within the repeatability of an extreme: the max/min spreads less "
                 "than one mean, U is on the safe side"] if ties else []
        out[name] = (hi[a] - lo[b], terms, how, notes)

    for cands, suffix in ((up, "_up"), (down, "_down")):
        range_form("E" + suffix, cands, False)
        if all(c["n"] >= 2 for c in cands):
            range_form("A" + suffix, cands, True)
            if cands:
                i = int(np.argmax([c["s_um"] for c in cands]))
                out["R" + suffix] = (4 * cands[i]["s_um"], [_term(4.0, "s", cands[i])], f"R{suffix} = 4 s({_at(cands[i])})", [])
    paired = len(up) == len(down) and up and all(abs(u["target_mm"] - d["target_mm"]) <= TARGET_TOLERANCE_MM
                                                 for u, d in zip(up, down))
    if paired:
        range_form("E", up + down, False)
        if all(c["n"] >= 2 for c in up + down):
            range_form("A", up + down, True)
        b = [u["mean_um"] - d["mean_um"] for u, d in zip(up, down)]
        i = int(np.argmax(np.abs(b)))
        sg = 1.0 if b[i] >= 0 else -1.0
        out["B"] = (abs(b[i]), [_term(sg, "mean", up[i]), _term(-sg, "mean", down[i])],
                    f"B = |x({_at(up[i])}) - x({_at(down[i])})|", [])
        m = len(b)
        out["B_mean"] = (sum(b) / m, [_term(1 / m, "mean", u) for u in up] + [_term(-1 / m, "mean", d) for d in down],
                         f"B_mean = mean over {m} targets of x(up) - x(down)", [])
        if len(up) >= 2:
            xbar = [(u["mean_um"] + d["mean_um"]) / 2 for u, d in zip(up, down)]
            a_, b_ = int(np.argmax(xbar)), int(np.argmin(xbar))
            out["M"] = (xbar[a_] - xbar[b_],
                        [_term(0.5, "mean", up[a_]), _term(0.5, "mean", down[a_]),
                         _term(-0.5, "mean", up[b_]), _term(-0.5, "mean", down[b_])],
                        f"M = xbar({up[a_]['target_mm']:+.4g} mm) - xbar({up[b_]['target_mm']:+.4g} mm)", [])
        if all(c["n"] >= 2 for c in up + down):
            best, form, how = -1.0, [], ""
            for j, (u, d, bj) in enumerate(zip(up, down, b)):
                sg = 1.0 if bj >= 0 else -1.0
                cands = [(2 * u["s_um"] + 2 * d["s_um"] + abs(bj),
                          [_term(2.0, "s", u), _term(2.0, "s", d), _term(sg, "mean", u), _term(-sg, "mean", d)],
                          f"R = 2 s(up) + 2 s(down) + |B_i| at {u['target_mm']:+.4g} mm"),
                         (4 * u["s_um"], [_term(4.0, "s", u)], f"R = 4 s({_at(u)})"),
                         (4 * d["s_um"], [_term(4.0, "s", d)], f"R = 4 s({_at(d)})")]
                for v, f, h in cands:
                    if v > best:
                        best, form, how = v, f, h
            out["R"] = (best, form, how, [])
    return out



# -- propagation: every value as mean + loadings on independent standard inputs ------------------------

@dataclass
class _Var:
    """A Gaussian quantity (um) in canonical form: mean + sum_k load[k] z_k + r z_own, where z are
    independent standard inputs (keys below) and r the part of its own (from a max)."""

    mean: float
    load: dict
    r: float = 0.0

    def __post_init__(self) -> None:
        self.var = sum(a * a for a in self.load.values()) + self.r * self.r  # fixed once built

    def cov(self, other: "_Var") -> float:
        small, big = (self.load, other.load) if len(self.load) < len(other.load) else (other.load, self.load)
        return sum(a * big.get(k, 0.0) for k, a in small.items())

    def __add__(self, other: "_Var") -> "_Var":
        load = dict(self.load)
        for k, a in other.load.items():
            load[k] = load.get(k, 0.0) + a
        return _Var(self.mean + other.mean, load, math.hypot(self.r, other.r))

    def scale(self, c: float) -> "_Var":
        return _Var(c * self.mean, {k: c * a for k, a in self.load.items()}, abs(c) * self.r)


def _phi(x: float) -> float:
    return math.exp(-0.5 * x * x) / math.sqrt(2 * math.pi)


def _Phi(x: float) -> float:
    return 0.5 * math.erfc(-x / math.sqrt(2))


def _max2(a: _Var, b: _Var) -> _Var:
    """max(a, b) as a Gaussian (Clark 1961): its mean and variance exactly for jointly normal a, b;
    its covariance with every input through the weights Phi(alpha), the rest as a part of its own."""
    theta2 = a.var + b.var - 2 * a.cov(b)
    if theta2 <= 1e-24:
        return a if a.mean >= b.mean else b
    theta = math.sqrt(theta2)
    al = (a.mean - b.mean) / theta
    wa, wb, ph = _Phi(al), _Phi(-al), _phi(al)
    m1 = a.mean * wa + b.mean * wb + theta * ph
    m2 = (a.mean ** 2 + a.var) * wa + (b.mean ** 2 + b.var) * wb + (a.mean + b.mean) * theta * ph
    load = {k: wa * v for k, v in a.load.items()}
    for k, v in b.load.items():
        load[k] = load.get(k, 0.0) + wb * v
    shared = sum(v * v for v in load.values())
    r2 = (a.r * wa) ** 2 + (b.r * wb) ** 2  # the operands' own parts, as far as they carry over
    # loadings of candidates that (almost) never set the max: moved into its own part, so the
    # running max of hundreds of targets does not carry every one of them
    tiny = 1e-3 * math.sqrt(shared)
    small = [k for k, v in load.items() if abs(v) < tiny]
    for k in small:
        v = load.pop(k)
        shared -= v * v
        r2 += v * v
    own = math.sqrt(max(m2 - m1 * m1 - shared - r2, 0.0))
    return _Var(m1, load, math.sqrt(r2 + own * own))


def _max(vs: list[_Var]) -> _Var:
    """max over `vs`, folded pairwise from the largest mean down (the usual order for Clark)."""
    vs = sorted(vs, key=lambda v: -v.mean)
    out = vs[0]
    for v in vs[1:]:
        if out.mean - v.mean > 8.0 * (math.sqrt(out.var) + math.sqrt(v.var)):
            break  # this one and all after it are below the max for sure (Phi(-8) ~ 6e-16)
        out = _max2(out, v)
    return out


def _min(vs: list[_Var]) -> _Var:
    return _max([v.scale(-1.0) for v in vs]).scale(-1.0)


class _Model:
    """The inputs of one leg's budget and the quantities built on them (module docstring)."""

    def __init__(self, inp: UncertaintyInputs, env: Environment, sens: dict[str, float], stroke_mm: float):
        self.inp, self.env, self.sens = inp, env, sens
        self.meta: dict = {}  # key -> (source, quantity, unit, u_input, distribution)
        c = self.common = []  # (key, ppm per unit of the input, u_input); a scale error eps -> 1e-3 eps P
        self._add(c, "laser", "laser scale error (stated accuracy, k = 2)", "ppm", inp.laser_accuracy_ppm / K_COVERAGE,
                  "normal, stated U / 2", 1.0)
        # n too small -> the laser reads long: eps = -dn
        self._add(c, "air temperature", "air temperature sensor error, via n", "K", inp.air_temp_u_c,
                  "standard uncertainty", -sens["temp_ppm_per_k"])
        self._add(c, "air pressure", "air pressure sensor error, via n", "Pa", inp.pressure_u_pa,
                  "standard uncertainty", -sens["pressure_ppm_per_pa"])
        self._add(c, "humidity", "humidity sensor error, via n", "%RH", inp.humidity_u_pct, "standard uncertainty",
                  -sens["humidity_ppm_per_pct"])
        if inp.misalignment_mm > 0 and stroke_mm > 0:
            bound = 1e6 * inp.misalignment_mm ** 2 / (8 * stroke_mm ** 2)
            self._add(c, "misalignment", f"cosine error s^2/(8 D^2), s = {inp.misalignment_mm:g} mm over "
                      f"D = {stroke_mm:.4g} mm, bound {bound:.3g} ppm", "ppm", bound / SQRT3, "rectangular +/- bound", 1.0)
        # NDE: x_norm = x - 1e-3 alpha (T - T_ref)(P - P_fixed): a sensor error dT is a scale error -alpha dT
        self._add(c, "material temperature", "material temperature sensor error (NDE)", "K", inp.material_temp_u_c,
                  "standard uncertainty", -inp.expansion_um_m_k)
        self.meta["expansion coefficient"] = ("expansion coefficient", "expansion coefficient error (NDE)", "um/m/K",
                                              inp.expansion_u_um_m_k, "standard uncertainty")

    def _add(self, lst, key, quantity, unit, u, dist, ppm_per_unit):
        self.meta[key] = (key, quantity, unit, u, dist)
        lst.append((key, ppm_per_unit, u))

    def mean_var(self, t: dict) -> _Var:
        """The mean deviation at one target and direction (dict from _stats_terms)."""
        inp, P = self.inp, t["target_mm"]
        cell = (t["direction"], round(P, 3))
        load = {key: 1e-3 * P * ppm * u for key, ppm, u in self.common}
        load["expansion coefficient"] = -1e-3 * t["material_dt_k"] * (P - inp.fixed_point_mm) * inp.expansion_u_um_m_k
        if inp.abbe_offset_mm > 0 and inp.abbe_angle_u_urad > 0:
            key = ("Abbe", round(P, 3))  # one angle per position: both directions see it
            self.meta[key] = ("Abbe", f"pitch/yaw angle at {P:+.4g} mm (offset {inp.abbe_offset_mm:g} mm)", "urad",
                              inp.abbe_angle_u_urad, "standard uncertainty")
            load[key] = 1e-3 * inp.abbe_offset_mm * inp.abbe_angle_u_urad
        if inp.dead_path_mm > 0 and self.env.dn_range_ppm > 0:
            key = ("dead path", cell)
            self.meta[key] = ("dead path", f"drift of n over the dead path {inp.dead_path_mm:g} mm at {_at(t)} "
                              f"(recorded range {self.env.dn_range_ppm:.3g} ppm)", "ppm",
                              self.env.dn_range_ppm / SQRT12, "rectangular over the recorded range")
            load[key] = 1e-3 * inp.dead_path_mm * self.env.dn_range_ppm / SQRT12
        n = max(t["n"], 1)
        if inp.laser_resolution_nm > 0:
            key = ("resolution", cell)
            self.meta[key] = ("resolution", f"laser resolution at {_at(t)}, averaged over {n} readings", "um",
                              1e-3 * inp.laser_resolution_nm / SQRT12, "rectangular")
            load[key] = 1e-3 * inp.laser_resolution_nm / SQRT12 / math.sqrt(n)
        key = ("mean", cell)
        self.meta[key] = ("repeatability", f"mean at {_at(t)} (s = {t['s_um']:.3g} um, n = {n})", "um",
                          t["s_um"] / math.sqrt(n), "type A, s / sqrt(n)")
        load[key] = t["s_um"] / math.sqrt(n)
        return _Var(t["mean_um"], load)

    def s_var(self, t: dict) -> _Var:
        """The estimator s at one target and direction: u(s) = s / sqrt(2 (n - 1))."""
        key = ("s", (t["direction"], round(t["target_mm"], 3)))
        u = t["s_um"] / math.sqrt(2 * max(t["n"] - 1, 1))
        self.meta[key] = ("repeatability", f"estimator s at {_at(t)} (n = {t['n']})", "um", u,
                          "type A, s / sqrt(2 (n - 1))")
        return _Var(t["s_um"], {key: u})

    def contributions(self, v: _Var) -> tuple[Contribution, ...]:
        """The rows of a budget: each input's loading as sensitivity * u_input; inputs of one source
        at several places (Abbe, dead path, resolution) summed in quadrature into one row."""
        rows: list[Contribution] = []
        grouped: dict[str, list[float]] = {}
        for key, a in v.load.items():
            source, quantity, unit, u, dist = self.meta[key]
            if isinstance(key, tuple) and key[0] in ("Abbe", "dead path", "resolution"):
                grouped.setdefault(key[0], []).append(a)
                continue
            if isinstance(key, tuple) and abs(a) < 1e-6 * max(math.sqrt(v.var), 1e-12):
                continue  # a target that (almost) never sets the value
            rows.append(Contribution(source, quantity, unit, u, a / u if u > 0 else 0.0, dist))
        for source, loads in grouped.items():
            total = math.sqrt(sum(a * a for a in loads))
            key = next(k for k in v.load if isinstance(k, tuple) and k[0] == source)
            _, quantity, unit, u, dist = self.meta[key]
            quantity = quantity.split(" at ")[0] + f", {len(loads)} place(s), independent"
            if source == "dead path":
                quantity = (f"drift of n over the dead path {self.inp.dead_path_mm:g} mm, {len(loads)} mean(s), "
                            f"independent (recorded range {self.env.dn_range_ppm:.3g} ppm)")
            rows.append(Contribution(source, quantity, unit, u, total / u if u > 0 else 0.0, dist))
        if v.r > 0:
            rows.append(Contribution("near-equal extremes", "which target sets the max/min (Clark 1961)", "um",
                                     v.r, 1.0, "from the candidates' spread"))
        return tuple(rows)


def _iso_vars(model: _Model, up: list[dict], down: list[dict]) -> dict[str, _Var]:
    """Each ISO 230-2 value as a _Var: max and min over ALL candidates, not only those found."""
    mu = {id(t): model.mean_var(t) for t in up + down}
    sv = {id(t): model.s_var(t) for t in up + down}
    out: dict[str, _Var] = {}

    def has_s(cands):
        return all(t["n"] >= 2 for t in cands)

    for cands, suffix in ((up, "_up"), (down, "_down")):
        if len(cands) >= 2:
            out["E" + suffix] = _max([mu[id(t)] for t in cands]) + _min([mu[id(t)] for t in cands]).scale(-1)
        if cands and has_s(cands):
            if len(cands) >= 2:
                out["A" + suffix] = (_max([mu[id(t)] + sv[id(t)].scale(2) for t in cands])
                                     + _min([mu[id(t)] + sv[id(t)].scale(-2) for t in cands]).scale(-1))
            out["R" + suffix] = _max([sv[id(t)].scale(4) for t in cands])
    paired = bool(up) and len(up) == len(down) and all(
        abs(u["target_mm"] - d["target_mm"]) <= TARGET_TOLERANCE_MM for u, d in zip(up, down))
    if not paired:
        return out
    both = up + down
    if len(up) >= 2:
        out["E"] = _max([mu[id(t)] for t in both]) + _min([mu[id(t)] for t in both]).scale(-1)
        xbar = [(mu[id(u)] + mu[id(d)]).scale(0.5) for u, d in zip(up, down)]
        out["M"] = _max(xbar) + _min(xbar).scale(-1)
    bi = [mu[id(u)] + mu[id(d)].scale(-1) for u, d in zip(up, down)]
    out["B"] = _max([b for b_i in bi for b in (b_i, b_i.scale(-1))])
    total = bi[0]
    for b_i in bi[1:]:
        total = total + b_i
    out["B_mean"] = total.scale(1 / len(bi))
    if has_s(both):
        if len(up) >= 2:
            out["A"] = (_max([mu[id(t)] + sv[id(t)].scale(2) for t in both])
                        + _min([mu[id(t)] + sv[id(t)].scale(-2) for t in both]).scale(-1))
        cands = []
        for u, d, b_i in zip(up, down, bi):
            abs_b = _max([b_i, b_i.scale(-1)])
            cands += [sv[id(u)].scale(2) + sv[id(d)].scale(2) + abs_b, sv[id(u)].scale(4), sv[id(d)].scale(4)]
        out["R"] = _max(cands)
    return out


@dataclass(frozen=True)
class LegBudget:
    """Every ISO 230-2 value's budget of one leg, the inputs and what was assumed."""

    leg: int
    values: dict[str, ValueBudget]
    inputs: UncertaintyInputs
    sensitivities: dict[str, Any]
    environment: Environment
    notes: list[str] = field(default_factory=list)

    def U(self, name: str) -> float | None:
        b = self.values.get(name)
        return None if b is None else b.U_um

    def to_json(self) -> dict[str, Any]:
        env = self.environment
        return {"k": K_COVERAGE, "inputs": asdict(self.inputs), "air_sensitivities": self.sensitivities,
                "refractive_index_range_ppm": env.dn_range_ppm, "notes": list(self.notes),
                "values": {k: v.to_json() for k, v in self.values.items()}}


def _stroke(stats) -> float:
    targets = [t.target_mm for t in stats]
    return (max(targets) - min(targets)) if targets else 0.0


def leg_budget(iso_leg, points: np.ndarray, inputs: UncertaintyInputs | None = None) -> LegBudget:
    """Uncertainty budgets of every ISO 230-2 value of `iso_leg` (procedures.reporting.iso230.LegIso230),
    evaluated on the leg's `points` (POINT_DTYPE: the environment and material temperatures)."""
    inp = inputs or UncertaintyInputs()
    pts = points[points["leg"] == iso_leg.leg] if points.dtype.names and "leg" in points.dtype.names else points
    env = Environment.of(pts)
    air_t = (sum(env.air_temp_c) / 2) if env.air_temp_c else 20.0
    air_p = (sum(env.pressure_pa) / 2) if env.pressure_pa else 101325.0
    air_h = (sum(env.humidity_pct) / 2) if env.humidity_pct else 50.0
    sens = air_sensitivities(air_t, air_p, air_h, inp.co2_ppm, inp.wavelength_nm)
    env = env.with_dn_range(pts, sens)
    temps = _target_temps(pts, inp.reference_temp_c)
    notes = []
    if env.material_temp_c is None:
        notes.append("no material temperature recorded: the NDE terms assume the reference temperature")
    model = _Model(inp, env, sens, _stroke(iso_leg.up + iso_leg.down))
    up, down = _stats_terms(iso_leg.up, 1, temps), _stats_terms(iso_leg.down, -1, temps)
    forms = _forms(iso_leg, temps)
    budgets = {}
    for name, v in _iso_vars(model, up, down).items():
        value = iso_leg.values.get(name)
        if value is None:
            continue
        how = forms.get(name, (None, None, "", []))[2]
        budgets[name] = ValueBudget(name, float(value), model.contributions(v),
                                    (how + "; " if how else "") + _HOW.get(name[0] if name != "B_mean" else name, ""))
    return LegBudget(iso_leg.leg, budgets, inp, sens, env, notes)


_HOW = {
    "E": "max and min of the target means over all candidates (Clark 1961), the scale terms correlated",
    "A": "max of x + 2s and min of x - 2s over all candidates (Clark 1961), the scale terms correlated",
    "M": "max and min of the bidirectional means over all candidates (Clark 1961)",
    "B": "max of |B_i| over all targets (Clark 1961); the scale terms cancel at one target",
    "B_mean": "a mean of the reversal values; the scale terms cancel",
    "R": "max over the targets' R_i (Clark 1961); only the repeatability seen in the data",
}


def table_budget(positions_mm: Iterable[float], s_um: float, n: int, inputs: UncertaintyInputs | None = None,
                 material_dt_k: float = 0.0, sens: dict[str, float] | None = None,
                 stroke_mm: float = 0.0) -> list[dict[str, float]]:
    """u and U (k = 2, um) of compensation table entries at `positions_mm`: each entry is a mean
    error of n approaches (scatter s_um) relative to the laser zero at 0 mm, so the
    length-proportional terms grow with |P| (evaluated over the stroke) and vanish at the zero."""
    inp = inputs or UncertaintyInputs()
    model = _Model(inp, Environment(None, None, None, None, None), sens or air_sensitivities(
        wavelength_nm=inp.wavelength_nm, co2_ppm=inp.co2_ppm), stroke_mm)
    out = []
    for p in positions_mm:
        v = model.mean_var(dict(direction=1, target_mm=float(p), mean_um=0.0, s_um=s_um, n=n,
                                material_dt_k=material_dt_k))
        u = math.sqrt(v.var)
        out.append({"position_mm": float(p), "u_um": u, "U_um": K_COVERAGE * u})
    return out
