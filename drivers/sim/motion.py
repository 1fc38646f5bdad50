"""Jerk-limited point-to-point moves of the simulated drive.

A trapezoidal velocity profile (acceleration `a`, cruise velocity `v`) smoothed by a moving
average over `t_jerk_s = a / jerk`: the standard way drives limit jerk (an FIR filter on the
set-point). The result is an S-curve whose acceleration ramps at `jerk` mm/s^3; it lasts
`t_jerk_s` longer than the trapezoid and keeps its peak velocity and acceleration. Positions are
exact (closed-form integrals of the trapezoid), so crossing times of the position-compare output
can be found to any precision.
"""

from __future__ import annotations

import math


class SmoothedMove:
    """A move of the nut from `p0` to `p1` (mm) starting at `t0` (s), cruise `v` mm/s,
    acceleration `a` mm/s^2, jerk `jerk` mm/s^3 (None or inf: plain trapezoid).

    Same interface as the drive's trapezoid: `duration`, `t_end`, `position(t)`, `velocity(t)`.
    """

    def __init__(self, p0: float, p1: float, t0: float, v: float, a: float, jerk: float | None = None):
        self.p0, self.p1, self.t0, self.v, self.a = float(p0), float(p1), float(t0), float(v), float(a)
        self.jerk = jerk
        self.sign = 1.0 if p1 >= p0 else -1.0
        d = abs(self.p1 - self.p0)
        self.length = d
        if d <= v * v / a:  # triangular: never reaches cruise velocity
            self.t_acc = math.sqrt(d / a)
            self.v_peak = a * self.t_acc
            self.t_cruise = 0.0
        else:
            self.t_acc = v / a
            self.v_peak = v
            self.t_cruise = (d - v * v / a) / v
        self.t_trap = 2 * self.t_acc + self.t_cruise
        self.t_jerk_s = 0.0 if not jerk or math.isinf(jerk) or d == 0.0 else a / float(jerk)
        self.duration = self.t_trap + self.t_jerk_s

    @property
    def t_end(self) -> float:
        return self.t0 + self.duration

    # trapezoid distance d(s) and its integral D(s), s = time since the start
    def _d(self, s: float) -> float:
        ta, tc, a, vp = self.t_acc, self.t_cruise, self.a, self.v_peak
        if s <= 0:
            return 0.0
        if s <= ta:
            return 0.5 * a * s * s
        if s <= ta + tc:
            return 0.5 * a * ta * ta + vp * (s - ta)
        if s < self.t_trap:
            r = self.t_trap - s
            return self.length - 0.5 * a * r * r
        return self.length

    def _D(self, s: float) -> float:
        ta, tc, a, vp, L = self.t_acc, self.t_cruise, self.a, self.v_peak, self.length
        if s <= 0:
            return 0.0
        if s <= ta:
            return a * s ** 3 / 6.0
        d1 = a * ta ** 3 / 6.0
        if s <= ta + tc:
            u = s - ta
            return d1 + 0.5 * a * ta * ta * u + 0.5 * vp * u * u
        s2 = ta + tc
        d2 = d1 + 0.5 * a * ta * ta * tc + 0.5 * vp * tc * tc
        if s <= self.t_trap:
            r = self.t_trap - s
            return d2 + L * (s - s2) - a / 6.0 * (ta ** 3 - r ** 3)
        d3 = d2 + L * ta - a / 6.0 * ta ** 3
        return d3 + L * (s - self.t_trap)

    def position(self, t: float) -> float:
        """Nut position (mm) at time t."""
        s = min(max(t - self.t0, 0.0), self.duration)
        tj = self.t_jerk_s
        if tj <= 0:
            dist = self._d(s)
        else:
            dist = (self._D(s) - self._D(s - tj)) / tj
        return self.p0 + self.sign * dist

    def velocity(self, t: float) -> float:
        """Signed velocity (mm/s) at time t."""
        s = t - self.t0
        if s <= 0 or s >= self.duration:
            return 0.0
        tj = self.t_jerk_s
        if tj <= 0:
            if s < self.t_acc:
                v = self.a * s
            elif s < self.t_acc + self.t_cruise:
                v = self.v_peak
            else:
                v = self.a * (self.t_trap - s)
            return self.sign * v
        return self.sign * (self._d(s) - self._d(s - tj)) / tj

    def time_at(self, position_mm: float, t_from: float | None = None) -> float | None:
        """First time (s) at which the move passes `position_mm`, at or after `t_from` (None
        when it does not within the move). Bisection: the position is monotone in time."""
        lo = self.t0 if t_from is None else max(self.t0, t_from)
        hi = self.t_end
        past = lambda t: (self.position(t) - position_mm) * self.sign >= 0  # noqa: E731
        if not past(hi):
            return None
        if past(lo):
            return lo
        for _ in range(60):  # 2^-60 of a move: far below a nanosecond
            mid = 0.5 * (lo + hi)
            if past(mid):
                hi = mid
            else:
                lo = mid
        return hi
