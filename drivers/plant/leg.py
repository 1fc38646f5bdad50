"""The plant: a physical model (digital twin) of one ball-screw leg.

Both the simulated drive (Modbus) and the simulated interferometer (serial) read the same
`LegPlant`, so what the drive does and what the laser sees stay consistent.

Coordinates and signs (see drivers.interfaces): `x_mm` is the motor/encoder position of the nut
relative to mid-stroke; the leg's true length is `nominal_length_mm + x_mm + error_um/1000`.
`error_um` is *true minus commanded* (positive = leg too long). Direction +1 = moving towards
larger x.

Error sources (each can be switched off by leaving it out of `enabled`), magnitudes from
shared/docs/domain.md section 4:
- ``lead``: cumulative lead error, a slope `lead_slope_um_per_m` over the stroke.
- ``longwave``: long-wave screw error terms `(wavelength_mm, amplitude_um, phase_rad)`.
- ``wobble``: once-per-revolution error at the screw lead `lead_mm`.
- ``backlash``: reversal; `reversal_um` = mean error approaching in -1 minus in +1, so the
  error is -reversal/2 approaching upwards and +reversal/2 approaching downwards.
  Variants (all 0 by default, so sessions and committed samples stay identical; issue 25):
  `reversal_um_per_k` makes the reversal change with the material temperature (the nut preload
  changes as the leg warms: reversal + reversal_um_per_k * (T - temp_ref_c)); `reversal_wear_um`
  makes it larger over the most-used part of the stroke (nut wear: + reversal_wear_um *
  max(0, 1 - ((x - reversal_wear_centre_mm) / reversal_wear_half_width_mm)^2)); `windup_mm` makes
  the reversal wind up over that length after each reversal (lost motion: the error starts at
  the old direction's value and approaches the new one as exp(-s / windup_mm), s = travel since
  the reversal).
- ``thermal``: the screw expands between its fixed bearing (at `bearing_mm`) and the nut:
  `expansion_ppm_per_k * (x - bearing_mm)/1000 * (T - temp_ref_c)` um, with the material
  temperature T following a first-order model heated by travel (`heating_k_per_m`, `tau_s`)
  towards an ambient that may swing (`ambient_swing_k`) or ramp (`ambient_ramp_k_per_h`).
  A leg warm by dT is longer by expansion_ppm_per_k * dT * (x - bearing_mm) / 1000 um: the
  station's normalisation to 20 degC (procedures/metrology/thermal.py) removes exactly this
  when the leg's material is configured as the plant's (fixed point = bearing_mm).
  Variant (0 by default): `expansion_gradient_ppm_per_k_per_m`, a temperature rise that grows
  along the screw from the bearing (the nut end runs warmer): the local expansion per K is
  expansion_ppm_per_k + gradient * (u - bearing_mm)/1000, so the error gains
  gradient * (x - bearing_mm)^2 / 2e6 * (T - temp_ref_c) um, growing with the square of position.
- ``load``: elastic compliance under axial load (compression positive shortens the leg):
  `-(bearing_compliance_um_per_kn + screw_compliance_um_per_kn_per_m*(x - bearing_mm)/1000) * load_kn`.
- ``drift``: setup/laser drift growing with time, `drift_um_per_h`, independent of position.
- ``scale``: a scale error of the measurement chain (cosine/Abbe, wavelength), `scale_ppm` of x.
- ``noise``: white measurement noise, `noise_um` standard deviation per reading.
- ``run_offset``: run-to-run scatter; a new offset (std `run_offset_um`) at every reversal.

Motion dynamics (how the leg moves, not a static error; docs/onthefly.md). Set by the drive as it
moves the nut (`set_velocity`, `stopped`); none of it is in `systematic_error_um`:
- the drive's servo lags its demand by `following_lag_up_s` / `following_lag_down_s` times the
  speed (the following error it reports; direction-dependent: gravity and friction differ);
- the leg end follows the motor encoder as a first-order lag: while moving at `v` mm/s the leg
  is `dynamic_lag_*_s * v` shorter than the encoder says (longer while moving down), so
  on-the-fly readings carry `-dynamic_lag_s * v * 1000` um (`dynamic_error_um`), which a
  stop-and-go reading after the dwell does not;
- after a stop the leg rings out: an overshoot of `settle_um_per_mm_s2` per mm/s^2 of
  deceleration in the direction of motion, decaying with `settling_tau_s` (a reading is stable
  after `settling_time_s`, 12 time constants: 0.72 s);
- the drive limits jerk to `jerk_mm_s3` (its trapezoid is smoothed over accel / jerk seconds;
  0 = not limited, the default; `with_leg_motion()` gives a real leg's `LEG_JERK_MM_S3`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

LEAD_MM = 5.0
"""The leg's screw lead, mm per revolution (the paper's positioner): where its once-per-revolution
error repeats (the plant's `lead_mm`, the reference twin's wobble)."""

LEG_JERK_MM_S3 = 2000.0
"""Jerk limit of a real leg's drive tuning: 50 ms to reach 100 mm/s^2 (docs/onthefly.md)."""

ALL_SOURCES = frozenset(
    {"lead", "longwave", "wobble", "backlash", "thermal", "load", "drift", "scale", "noise", "run_offset"}
)


@dataclass(frozen=True)
class PlantConfig:
    """Physical parameters of one leg. Units are in the names."""

    nominal_length_mm: float = 1095.85  # leg length at mid-stroke (the paper's positioner)
    stroke_half_mm: float = 90.0  # usable stroke is +/- this around mid-stroke
    lead_mm: float = LEAD_MM  # screw lead (travel per revolution)
    lead_slope_um_per_m: float = 9.0  # the paper's "linear deviation of 9 um/m"
    longwave: tuple[tuple[float, float, float], ...] = ((120.0, 0.6, 0.4), (45.0, 0.25, 1.9))
    wobble_amplitude_um: float = 0.2
    wobble_phase_rad: float = 0.7
    reversal_um: float = 1.0
    reversal_um_per_k: float = 0.0  # variant: the reversal changes with material temperature
    reversal_wear_um: float = 0.0  # variant: extra reversal over the most-used part of the stroke (nut wear)
    reversal_wear_centre_mm: float = 0.0
    reversal_wear_half_width_mm: float = 90.0
    windup_mm: float = 0.0  # variant: lost motion winding up over this travel after each reversal (0 = at once)
    expansion_ppm_per_k: float = 11.5  # steel
    expansion_gradient_ppm_per_k_per_m: float = 0.0  # variant: thermal expansion growing along the screw
    bearing_mm: float = -150.0  # fixed bearing, below the stroke
    temp_ref_c: float = 20.0  # error-free temperature (lengths are normalised to 20 C)
    ambient_temp_c: float = 20.0
    initial_temp_c: float = 20.0
    heating_k_per_m: float = 0.25  # material temperature rise per metre of nut travel
    tau_s: float = 1800.0  # thermal time constant of the screw
    bearing_compliance_um_per_kn: float = 1.5
    screw_compliance_um_per_kn_per_m: float = 15.5  # L/(E*A), d = 20 mm, E = 2.06e5 N/mm^2
    load_per_pass_n: tuple[float, ...] = (0.0,)  # axial load, cycled at every new pass
    drift_um_per_h: float = 0.15
    scale_ppm: float = 0.0
    noise_um: float = 0.03
    run_offset_um: float = 0.04
    enabled: frozenset[str] = field(default_factory=lambda: ALL_SOURCES)
    # ambient cycling (air conditioning, day/night): ambient = ambient_temp_c + swing*sin(2 pi t/period);
    # makes the material temperature non-monotonic in time, so thermal and drift are separable
    ambient_swing_k: float = 0.0
    ambient_period_s: float = 3600.0
    # the hall warming (or cooling) steadily: ambient += ambient_ramp_k_per_h * hours since the
    # session start; the material follows with tau_s (a leg warming during a sweep)
    ambient_ramp_k_per_h: float = 0.0
    # -- motion dynamics (see the module docstring; additive: defaults keep static results) --
    # 0 = not limited: the default keeps the timing of the committed sample recordings (a jerk
    # limit lengthens every move by accel/jerk); LEG_JERK_MM_S3 is a real leg's (bench, docs)
    jerk_mm_s3: float = 0.0
    following_lag_up_s: float = 0.002
    following_lag_down_s: float = 0.0025
    dynamic_lag_up_s: float = 0.00012  # 1.2 um at 10 mm/s moving up
    dynamic_lag_down_s: float = 0.00008
    settling_tau_s: float = 0.06
    settle_um_per_mm_s2: float = 0.01  # 1 um overshoot after a 100 mm/s^2 stop

    def __post_init__(self) -> None:
        unknown = set(self.enabled) - ALL_SOURCES
        if unknown:
            raise ValueError(f"unknown error sources {sorted(unknown)}; known: {sorted(ALL_SOURCES)}")
        if self.tau_s <= 0 or self.lead_mm <= 0 or self.stroke_half_mm <= 0:
            raise ValueError("tau_s, lead_mm and stroke_half_mm must be positive")
        if self.ambient_period_s <= 0:
            raise ValueError("ambient_period_s must be positive")
        if self.windup_mm < 0 or self.reversal_wear_half_width_mm <= 0:
            raise ValueError("windup_mm must be >= 0 and reversal_wear_half_width_mm positive")
        if self.jerk_mm_s3 < 0 or self.settling_tau_s < 0 or min(
                self.following_lag_up_s, self.following_lag_down_s, self.dynamic_lag_up_s, self.dynamic_lag_down_s) < 0:
            raise ValueError("jerk_mm_s3 (0 = not limited), the lags and settling_tau_s must be >= 0")

    def following_lag_s(self, velocity_mm_s: float) -> float:
        """The servo's following-error lag for a move at `velocity_mm_s` (signed), s."""
        return self.following_lag_up_s if velocity_mm_s >= 0 else self.following_lag_down_s

    def dynamic_lag_s(self, velocity_mm_s: float) -> float:
        """Encoder-to-leg-end lag for a move at `velocity_mm_s` (signed), s."""
        return self.dynamic_lag_up_s if velocity_mm_s >= 0 else self.dynamic_lag_down_s

    @property
    def settling_time_s(self) -> float:
        """Time after a stop until the ring-out is below 1e-5 of its start (12 time constants):
        from then on the leg is settled, its ring-out exactly 0 (so a reading after the dwell is
        the static one, to the last digit)."""
        return 12.0 * self.settling_tau_s

    def with_leg_motion(self, jerk_mm_s3: float = LEG_JERK_MM_S3) -> "PlantConfig":
        """This configuration with a real leg's jerk limit (the other motion dynamics are on by default)."""
        return replace(self, jerk_mm_s3=float(jerk_mm_s3))

    def only(self, *sources: str) -> "PlantConfig":
        """This configuration with only the named error sources switched on."""
        return replace(self, enabled=frozenset(sources))

    def without(self, *sources: str) -> "PlantConfig":
        """This configuration with the named error sources switched off."""
        return replace(self, enabled=frozenset(self.enabled) - set(sources))

    @property
    def compliance_um_per_kn(self) -> float:
        """Minus d(error)/d(load) at mid-stroke, um per kN (the diagnosis' parameter)."""
        return self.bearing_compliance_um_per_kn + self.screw_compliance_um_per_kn_per_m * (0.0 - self.bearing_mm) / 1000.0


def screw_error_um(cfg: PlantConfig, x_mm):
    """Position-only part of the error (lead slope, long-wave terms, wobble), um. Vectorised."""
    x = np.asarray(x_mm, dtype=float)
    e = np.zeros_like(x)
    on = cfg.enabled
    if "lead" in on:
        e = e + cfg.lead_slope_um_per_m * x / 1000.0
    if "longwave" in on:
        for wavelength_mm, amplitude_um, phase_rad in cfg.longwave:
            e = e + amplitude_um * np.sin(2 * np.pi * x / wavelength_mm + phase_rad)
    if "wobble" in on:
        e = e + cfg.wobble_amplitude_um * np.sin(2 * np.pi * x / cfg.lead_mm + cfg.wobble_phase_rad)
    return e


def reversal_um(cfg: PlantConfig, x_mm, temp_c):
    """The reversal (mean error approaching in -1 minus in +1, um) at position `x_mm` and
    material temperature `temp_c`, with the temperature and wear variants. Vectorised."""
    x = np.asarray(x_mm, dtype=float)
    r = cfg.reversal_um + cfg.reversal_um_per_k * (np.asarray(temp_c, dtype=float) - cfg.temp_ref_c)
    if cfg.reversal_wear_um:
        u = (x - cfg.reversal_wear_centre_mm) / cfg.reversal_wear_half_width_mm
        r = r + cfg.reversal_wear_um * np.maximum(0.0, 1.0 - u * u)
    return r + 0.0 * x


def systematic_error_um(cfg: PlantConfig, x_mm, direction, temp_c, load_n, t_s, since_reversal_mm=np.inf):
    """Deterministic error (true minus commanded), um, excluding noise and run offsets.

    All arguments broadcast: `x_mm` position, `direction` +1/-1 of the last motion,
    `temp_c` material temperature, `load_n` axial load (compression positive), `t_s` time since
    the start of the session (for drift), `since_reversal_mm` travel since the last reversal
    (for the lost-motion wind-up; inf = wound up).
    """
    x = np.asarray(x_mm, dtype=float)
    on = cfg.enabled
    e = screw_error_um(cfg, x)
    if "backlash" in on:
        d = np.sign(np.asarray(direction, dtype=float))
        r = reversal_um(cfg, x, temp_c)
        e = e - 0.5 * r * d
        if cfg.windup_mm > 0:
            # the error starts at the old direction's value and winds up to the new one
            e = e + r * d * np.exp(-np.asarray(since_reversal_mm, dtype=float) / cfg.windup_mm)
    if "thermal" in on:
        dt_k = np.asarray(temp_c, dtype=float) - cfg.temp_ref_c
        e = e + cfg.expansion_ppm_per_k * (x - cfg.bearing_mm) / 1000.0 * dt_k
        if cfg.expansion_gradient_ppm_per_k_per_m:
            e = e + cfg.expansion_gradient_ppm_per_k_per_m * (x - cfg.bearing_mm) ** 2 / 2e6 * dt_k
    if "load" in on:
        load_kn = np.asarray(load_n, dtype=float) / 1000.0
        c = cfg.bearing_compliance_um_per_kn + cfg.screw_compliance_um_per_kn_per_m * (x - cfg.bearing_mm) / 1000.0
        e = e - c * load_kn
    if "drift" in on:
        e = e + cfg.drift_um_per_h * np.asarray(t_s, dtype=float) / 3600.0
    if "scale" in on:
        e = e + cfg.scale_ppm * x / 1000.0
    return e


class LegPlant:
    """The stateful leg: nut position, direction of last motion, temperature, pass, load.

    Not thread-safe by itself; the simulated rig serialises access with its own lock.
    """

    def __init__(self, cfg: PlantConfig, seed: int = 0, t0_s: float = 0.0):
        self.cfg = cfg
        self._rng = np.random.default_rng(seed)
        self.x_mm = 0.0
        self.direction = 1
        self.temp_c = cfg.initial_temp_c
        self._t_last_s = t0_s
        self.t0_s = t0_s
        self.pass_index = 0
        self._pass_offset_um = self._draw_offset()
        self.load_n = cfg.load_per_pass_n[0] if cfg.load_per_pass_n else 0.0
        self._reversal_x_mm = -math.inf  # where the last reversal happened (lost-motion wind-up)
        self._zero_um = 0.0
        # motion dynamics: speed now (mm/s, signed) and the ring-out of the last stop
        self.velocity_mm_s = 0.0
        self._ring = (0.0, 0.0)  # (time of the stop, overshoot um at that time)

    # -- time evolution -------------------------------------------------------------------
    def _advance_thermal(self, t_s: float, travel_mm: float = 0.0) -> None:
        dt = max(0.0, t_s - self._t_last_s)
        heat_k = self.cfg.heating_k_per_m * abs(travel_mm) / 1000.0
        amb = self.cfg.ambient_temp_c
        if self.cfg.ambient_swing_k:
            # ambient at the middle of the interval: intervals are short against the period
            t_mid = 0.5 * (t_s + self._t_last_s) - self.t0_s
            amb += self.cfg.ambient_swing_k * math.sin(2 * math.pi * t_mid / self.cfg.ambient_period_s)
        if self.cfg.ambient_ramp_k_per_h:
            # ambient at the middle of the interval, as for the swing: intervals are short against tau_s
            amb += self.cfg.ambient_ramp_k_per_h * (0.5 * (t_s + self._t_last_s) - self.t0_s) / 3600.0
        if dt == 0.0:
            self.temp_c += heat_k
        else:
            decay = math.exp(-dt / self.cfg.tau_s)
            # constant heating rate over the interval: exact first-order response
            rate_k_s = heat_k / dt
            self.temp_c = amb + (self.temp_c - amb) * decay + rate_k_s * self.cfg.tau_s * (1.0 - decay)
        self._t_last_s = max(self._t_last_s, t_s)

    def _draw_offset(self) -> float:
        if "run_offset" in self.cfg.enabled and self.cfg.run_offset_um > 0:
            return float(self._rng.normal(0.0, self.cfg.run_offset_um))
        return 0.0

    def move(self, to_mm: float, t_end_s: float) -> None:
        """The nut has moved to `to_mm`, arriving at time `t_end_s`."""
        travel = to_mm - self.x_mm
        if travel != 0.0:
            new_dir = 1 if travel > 0 else -1
            if new_dir != self.direction:
                self._reversal_x_mm = self.x_mm
                self._new_pass(new_dir)
        self._advance_thermal(t_end_s, travel)
        self.x_mm = float(to_mm)

    def _new_pass(self, new_dir: int) -> None:
        self.direction = new_dir
        self.pass_index += 1
        self._pass_offset_um = self._draw_offset()
        loads = self.cfg.load_per_pass_n
        if loads:
            self.load_n = float(loads[self.pass_index % len(loads)])

    # -- motion dynamics (set by the drive) ---------------------------------------------------
    def set_velocity(self, velocity_mm_s: float) -> None:
        """The nut moves at `velocity_mm_s` now (signed, mm/s; 0 = at rest)."""
        self.velocity_mm_s = float(velocity_mm_s)

    def stopped(self, t_s: float, direction: int, decel_mm_s2: float) -> None:
        """The nut came to rest at `t_s` after decelerating at `decel_mm_s2` while moving in
        `direction`: the leg overshoots and rings out (`settle_um_per_mm_s2`, `settling_tau_s`)."""
        self.velocity_mm_s = 0.0
        self._ring = (float(t_s), float(np.sign(direction)) * self.cfg.settle_um_per_mm_s2 * abs(decel_mm_s2))

    def dynamic_error_um(self, t_s: float) -> float:
        """Leg end minus encoder beyond the static error, um: the speed-proportional lag while
        moving, the decaying overshoot after a stop (module docstring)."""
        v = self.velocity_mm_s
        if v != 0.0:
            return -self.cfg.dynamic_lag_s(v) * v * 1000.0
        t_stop, amp_um = self._ring
        if amp_um == 0.0 or self.cfg.settling_tau_s <= 0 or not 0.0 <= t_s - t_stop < self.cfg.settling_time_s:
            return 0.0
        return amp_um * math.exp(-(t_s - t_stop) / self.cfg.settling_tau_s)

    # -- observations -----------------------------------------------------------------------
    def error_um(self, t_s: float) -> float:
        """Systematic error now (true minus commanded at the nut), um; with the motion dynamics
        (`dynamic_error_um`) on top."""
        self._advance_thermal(t_s)
        return float(
            systematic_error_um(self.cfg, self.x_mm, self.direction, self.temp_c, self.load_n, t_s - self.t0_s,
                                self.since_reversal_mm)
        ) + self.dynamic_error_um(t_s)

    @property
    def since_reversal_mm(self) -> float:
        """Travel since the last reversal, mm (inf before the first one)."""
        return abs(self.x_mm - self._reversal_x_mm)

    def true_position_mm(self, t_s: float) -> float:
        return self.x_mm + self.error_um(t_s) / 1000.0

    def measured_position_mm(self, t_s: float, averaging_s: float = 0.0) -> float:
        """What an ideal-but-noisy interferometer reads now, relative to its zero, mm.

        Averaging over `averaging_s` reduces the white noise by sqrt(averaging / 0.1 s).
        """
        noise = 0.0
        if "noise" in self.cfg.enabled and self.cfg.noise_um > 0:
            n_eff = max(1.0, averaging_s / 0.1)
            noise = float(self._rng.normal(0.0, self.cfg.noise_um / math.sqrt(n_eff)))
        return self.true_position_mm(t_s) + (self._pass_offset_um + noise - self._zero_um) / 1000.0

    NOISE_SLOT_S = 0.1
    """The measurement noise's correlation time: `measured_position_mm` averages it as
    sqrt(averaging / 0.1 s), i.e. one independent value per 0.1 s."""

    def measured_positions_mm(self, times_s) -> np.ndarray:
        """What an ideal-but-noisy interferometer samples at each of `times_s` (ascending, a short
        span at rest, e.g. a streaming laser's frames since its last batch), unaveraged: the
        systematic error taken once, at the last time; the noise one value per 0.1 s slot
        (NOISE_SLOT_S), so the mean of the samples over a window has the noise a reading averaged
        over it has (`measured_position_mm`)."""
        base = self.true_position_mm(float(times_s[-1])) + (self._pass_offset_um - self._zero_um) / 1000.0
        if not ("noise" in self.cfg.enabled and self.cfg.noise_um > 0):
            return np.full(len(times_s), base)
        slots = np.floor(np.asarray(times_s, dtype=float) / self.NOISE_SLOT_S + 1e-9).astype(np.int64)
        noise = np.empty(len(slots))
        held = getattr(self, "_noise_slot", None)  # (slot, um) of the last sample, kept across batches
        for i, slot in enumerate(slots):
            if held is None or held[0] != slot:
                held = (int(slot), float(self._rng.normal(0.0, self.cfg.noise_um)))
            noise[i] = held[1]
        self._noise_slot = held
        return base + noise / 1000.0

    def zero_here(self, t_s: float) -> None:
        """Set the interferometer zero so that the current true position reads as x_mm."""
        self._zero_um = self.error_um(t_s) + self._pass_offset_um

    def material_temp_c(self, t_s: float) -> float:
        self._advance_thermal(t_s)
        return self.temp_c


def default_leg_configs(seed: int = 0, legs: int = 6, base: PlantConfig | None = None) -> list[PlantConfig]:
    """Six legs that look alike (same manufacturing) with small differences in scale and offset,
    as the paper observed. Deterministic for a seed."""
    base = base or PlantConfig()
    rng = np.random.default_rng(seed + 7919)
    out = []
    for _ in range(legs):
        k = float(rng.uniform(0.8, 1.2))
        out.append(
            replace(
                base,
                lead_slope_um_per_m=base.lead_slope_um_per_m * k,
                longwave=tuple((w, a * float(rng.uniform(0.8, 1.2)), p + float(rng.normal(0, 0.2))) for w, a, p in base.longwave),
                wobble_amplitude_um=base.wobble_amplitude_um * float(rng.uniform(0.7, 1.3)),
                reversal_um=base.reversal_um * float(rng.uniform(0.6, 1.4)),
                bearing_mm=base.bearing_mm + float(rng.uniform(-20, 20)),
            )
        )
    return out
