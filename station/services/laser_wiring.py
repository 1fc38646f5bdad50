"""Which interferometer client a station opens, by `[interferometer] protocol` (the composition
root's part for the laser; station/services/wiring.py calls it).

- "station": drivers.interferometer.SerialInterferometer (its own line protocol).
- "linef1": drivers.linef1.LineF1Interferometer (the µLine-F1 / HPI-3D stream): it is given the
  station's refractive-index equation (Ciddor, procedures/metrology/air.py, with the configured
  vacuum wavelength and CO2), the rig's clock (its samples are time-stamped on it) and the
  instrument's identity from [metrology] model / serial (the protocol has no identity query).
"""

from __future__ import annotations


from drivers.interfaces import Clock, Interferometer

LINEF1_EQUATION = "ciddor"
"""The equation the station applies to a µLine-F1's raw distance (recorded in the session)."""


def air_index(cfg, equation: str = LINEF1_EQUATION):
    """(temp_c, pressure_pa, humidity_pct) -> refractive index of air at the configured vacuum
    wavelength and CO2 ([metrology] wavelength_nm, co2_ppm)."""
    from procedures.metrology.air import refractive_index

    def index(temp_c: float, pressure_pa: float, humidity_pct: float) -> float:
        return float(refractive_index(equation, cfg.metrology.wavelength_nm, temp_c, pressure_pa, humidity_pct,
                                      cfg.metrology.co2_ppm))
    return index


def open_laser(cfg, port: str, clock: Clock | None = None, *, sim: bool = False) -> Interferometer:
    """The interferometer client for `port` by cfg's protocol. `clock`: the rig's (time stamps
    of a streaming laser; the station protocol's client measures its timeouts on real time)."""
    if cfg.interferometer.protocol == "linef1":
        from drivers.linef1 import LineF1Interferometer
        from drivers.linef1.protocol import BAUDRATE

        baud = cfg.interferometer.baudrate if cfg.interferometer.baudrate != 115200 else BAUDRATE
        model = cfg.metrology.model or ("simulated HPI-3D (uLine-F1)" if sim else "HPI-3D (uLine-F1)")
        serial_number = cfg.metrology.serial or ("SIM-LF1-0001" if sim else "")
        return LineF1Interferometer(port, baudrate=baud, timeout_s=cfg.interferometer.timeout_s, clock=clock,
                                    index=air_index(cfg), equation=LINEF1_EQUATION.upper(),
                                    wavelength_nm=cfg.metrology.wavelength_nm, co2_ppm=cfg.metrology.co2_ppm,
                                    vendor="Lasertex" if not sim else "StationSim", model=model,
                                    serial_number=serial_number)
    from drivers.interferometer.client import SerialInterferometer

    if sim:
        return SerialInterferometer(port, timeout_s=cfg.interferometer.timeout_s)
    return SerialInterferometer(port, baudrate=cfg.interferometer.baudrate, timeout_s=cfg.interferometer.timeout_s)


def sim_rig_laser_options(cfg) -> dict:
    """SimRig keyword arguments for cfg's interferometer protocol."""
    if cfg.interferometer.protocol == "linef1":
        return {"laser_protocol": "linef1", "air_index": air_index(cfg)}
    return {}




class _RecordedStationCompensation:
    """A replay's interferometer client whose `compensation()` is the recording's record where the
    station applied the index itself (a µLine-F1 session, mode STATION): the replay instrument
    speaks the station's protocol, whose COMP? cannot say that. Everything else is the client's."""

    def __init__(self, laser, record: dict):
        self._laser = laser
        self._record = record

    def compensation(self) -> dict:
        return dict(self._record)

    def __getattr__(self, name):
        return getattr(self._laser, name)


def replay_laser(laser, recorded_compensation: str | None):
    """The interferometer a replay sweeps with: `laser`, answering the recorded compensation record
    itself when that record says the station applied the index (mode STATION), so the replayed
    session records the same text and `station recorrect` works on it too."""
    import json

    try:
        record = json.loads(recorded_compensation or "")
    except ValueError:
        return laser
    if isinstance(record, dict) and str(record.get("mode", "")).upper() == "STATION":
        return _RecordedStationCompensation(laser, record)
    return laser
