"""Measuring the transports' latency apart from the leg's lag (procedures/acquisition/latency.py) on
the simulated rig: real Modbus TCP on loopback, the lasers on ptys, known delays given to the
simulated transports (SimRig's laser_latency_s, laser_jitter_s, drive_delay_s, drive_jitter_s)."""

from __future__ import annotations

import logging

import pytest

from bench.bench_latency import measure
from drivers.linef1.client import LineF1Interferometer
from drivers.modbus.client import connect_axes
from drivers.plant.leg import default_leg_configs
from drivers.sim.rig import SimRig
from procedures.acquisition.latency import measure_latency, transport_delay
from procedures.engine.control import RunControl
from procedures.vocabulary import InputError

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

SEED = 1
LASER_LATENCY_S = 0.003
LASER_JITTER_S = 0.002
DRIVE_DELAY_S = (0.0005, 0.0005)  # symmetric: the middle stamp is the instant the drive read
DRIVE_JITTER_S = 0.0002
TOLERANCE_MS = 0.15
"""How close the measured delay must come to the injected one: 5 standard errors of the mean of
two directions' (0.03 ms with 2 cycles at 10 and 20 mm/s, bench/bench_latency.py)."""


@pytest.fixture(scope="module")
def reports():
    delays = dict(drive_delay_s=DRIVE_DELAY_S, drive_jitter_s=DRIVE_JITTER_S)
    latched = measure("station", SEED, **delays)
    streamed = measure("linef1", SEED, LASER_LATENCY_S, LASER_JITTER_S, **delays)
    return latched, streamed


def test_an_injected_laser_delay_is_recovered_apart_from_the_legs_own_lag(reports):
    latched, streamed = reports
    cfg = default_leg_configs(SEED, 1)[0]
    # the latched laser sees the leg's lag alone (no transport between the compare pulse and the latch)
    lag = {d.direction: d.lag_ms for d in latched.lags}
    assert lag[1] == pytest.approx(cfg.dynamic_lag_up_s * 1000.0, abs=0.03)
    assert lag[-1] == pytest.approx(cfg.dynamic_lag_down_s * 1000.0, abs=0.03)
    # the streamed one the leg's lag and the delay: their difference is the injected latency
    d = transport_delay(streamed, latched)
    assert d.delay_ms == pytest.approx(LASER_LATENCY_S * 1000.0, abs=TOLERANCE_MS)
    assert d.disagreement_ms < TOLERANCE_MS  # the delay has no direction
    assert 0.0 < d.stderr_ms < TOLERANCE_MS / 3


def test_the_modbus_round_trip_and_its_spread_are_measured(reports):
    latched, streamed = reports
    low_ms = 1000.0 * sum(DRIVE_DELAY_S)
    for poll in (latched.poll_rest, streamed.poll_rest, streamed.poll_traced):
        assert low_ms - 1e-6 <= poll.min_ms and poll.max_ms <= low_ms + 1000.0 * DRIVE_JITTER_S + 1e-6
        assert poll.median_ms == pytest.approx(low_ms + 500.0 * DRIVE_JITTER_S, abs=0.03)
        assert poll.std_ms == pytest.approx(1000.0 * DRIVE_JITTER_S / 12 ** 0.5, rel=0.2)  # uniform
    assert streamed.poll_traced.count > 1000 and latched.poll_traced is None


def test_the_streams_arrival_jitter_is_measured_against_its_frame_grid(reports):
    latched, streamed = reports
    s = streamed.stream
    assert latched.stream is None
    assert s.frames >= 240 and s.lost == 0
    jitter_ms = 1000.0 * LASER_JITTER_S
    assert 0.9 * jitter_ms <= s.jitter.max_ms <= jitter_ms + 0.05
    assert s.jitter.median_ms == pytest.approx(jitter_ms / 2, abs=0.2)
    assert abs(s.drift_ppm) < 20.0  # the simulated instrument keeps the nominal rate


def test_an_asymmetric_modbus_link_moves_the_drives_stamps_and_is_measured_with_the_delay():
    """The drive's stamp is the middle of its request: a request leg 1 ms longer than the reply
    makes the stamp 0.5 ms early, so the laser's stamps read 0.5 ms later against them."""
    delays = dict(drive_delay_s=(0.0012, 0.0002), cycles=1)
    latched = measure("station", SEED, **delays)
    streamed = measure("linef1", SEED, LASER_LATENCY_S, 0.0, **delays)
    assert transport_delay(streamed, latched).delay_ms == pytest.approx(3.5, abs=TOLERANCE_MS)


def test_a_stroke_outside_the_soft_limits_or_one_speed_is_refused_before_any_motion():
    cfgs = [c.with_leg_motion() for c in default_leg_configs(SEED, 1)]
    with SimRig(time_scale=0.0, seed=SEED, legs=1, configs=cfgs, laser_protocol="linef1") as rig:
        axis = connect_axes(rig.drive_url, [1], clock=rig.clock)[1]
        laser = LineF1Interferometer(rig.laser_port, clock=rig.clock)
        try:
            axis.enable()
            before = axis.status().position_mm
            lim = axis.limits()
            with pytest.raises(InputError, match="soft limits"):
                list(measure_latency(1, axis, laser, rig.clock, RunControl(), lim.min_mm - 1.0, 0.0))
            with pytest.raises(InputError, match="two distinct speeds"):
                list(measure_latency(1, axis, laser, rig.clock, RunControl(), -50.0, 50.0, speeds_mm_s=(10.0, 10.0)))
            assert axis.status().position_mm == before
        finally:
            laser.close()
            axis.close()


def test_a_latency_on_the_station_protocols_laser_is_refused_with_a_reason():
    with pytest.raises(ValueError, match="compare pulse"):
        SimRig(laser_protocol="station", laser_latency_s=0.003)


def test_with_the_reflector_on_the_nut_the_streamed_speed_lag_is_the_delay_alone():
    """No leg between the encoder and the beam (the plant's lag taken out): no reference needed."""
    nut = measure("linef1", SEED, LASER_LATENCY_S, 0.0, drive_delay_s=DRIVE_DELAY_S, cycles=1, on_nut=True)
    for lag in nut.lags:
        assert lag.lag_ms == pytest.approx(LASER_LATENCY_S * 1000.0, abs=TOLERANCE_MS)


def test_the_floor_of_the_arrivals_follows_an_instrument_rate_off_the_nominal_one():
    """Arrivals from an instrument 100 ppm slow, late by 3 ms and a uniform 0..2 ms: the floor's
    slope is the rate, the jitter above it the draws (stream_jitter alone)."""
    import numpy as np

    from procedures.acquisition.latency import stream_jitter

    rng = np.random.default_rng(7)
    n = np.arange(1, 501)
    true_period_s = 0.04 * (1 + 100e-6)
    draws = rng.uniform(0.0, 0.002, n.size)
    keep = np.ones(n.size, bool)
    keep[[100, 101, 300]] = False  # lost frames keep their numbers
    arrivals = list(zip(n[keep].tolist(), (5.0 + n * true_period_s + 0.003 + draws)[keep].tolist()))
    s = stream_jitter(arrivals, 0.04)
    assert s.lost == 3 and s.frames == 497
    assert s.drift_ppm == pytest.approx(100.0, abs=10.0)
    assert s.jitter.max_ms == pytest.approx(2.0, abs=0.1) and s.jitter.median_ms == pytest.approx(1.0, abs=0.15)



def test_a_configured_rig_is_measured_and_its_delay_taken_against_a_saved_reference(tmp_path, capsys):
    """bench/bench_latency.py --config: the path a real bench takes (here the configured simulated
    rig, no delay given to its transports: d = 0), the latched report saved, the streamed one
    measured against it; a file that is not a report is refused in one line."""
    import re

    from bench.bench_latency import main

    base = '[drive]\nurl = "sim"\n[interferometer]\nport = "sim"\n{}[sim]\nseed = 3\n'
    (tmp_path / "station.toml").write_text(base.format(""))
    (tmp_path / "linef1.toml").write_text(base.format('protocol = "linef1"\n'))
    ref = tmp_path / "ref.json"
    common = ["--leg", "2", "--cycles", "1", "--stroke", "-40", "40"]
    assert main(["--config", str(tmp_path / "station.toml"), *common, "--save", str(ref)]) == 0
    assert main(["--config", str(tmp_path / "linef1.toml"), *common, "--reference", str(ref)]) == 0
    out = capsys.readouterr().out
    delay = float(re.search(r"behind the drive's polls: ([-+0-9.]+) ms", out).group(1))
    assert abs(delay) < TOLERANCE_MS
    (tmp_path / "bad.json").write_text('{"leg": 2}')
    assert main(["--config", str(tmp_path / "linef1.toml"), *common, "--reference", str(tmp_path / "bad.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.json: not a latency report" in err[0]
