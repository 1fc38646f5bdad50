"""Twins of the diagnosis built from files or the simulated plant, for both front ends
(`station diagnose --twin`, the terminal UI's Diagnosis page): MODEL.json, REFERENCE.h5,
sim:CONFIG.toml or sim:default. The simulated plant's systematic error is made a twin here, in
the station layer, so procedures never import the simulator."""

from __future__ import annotations

import tomllib
from dataclasses import fields, replace
from pathlib import Path

from procedures.diagnosis.twin import ExternalTwin, twin_from_model, twin_from_recording
from procedures.errors import InputError


def load_twin(spec: str):
    """The twin named by --twin: MODEL.json, REFERENCE.h5, sim:CONFIG.toml or sim:default."""
    if spec.startswith("sim:"):
        return sim_twin(spec[4:])
    path = Path(spec)
    if not path.exists():
        raise InputError(f"--twin {spec}: no such file (give MODEL.json, REFERENCE.h5 or sim:CONFIG.toml)")
    if path.suffix.lower() == ".json":
        from procedures.fit.model_io import load_model

        return twin_from_model(load_model(path), str(path))
    if path.suffix.lower() in (".h5", ".hdf5"):
        from procedures.recording.reader import read_session

        return twin_from_recording(read_session(path).points, str(path))
    raise InputError(f"--twin {spec}: unknown kind of twin (expected .json, .h5 or sim:CONFIG.toml)")


def _plant_configs(spec: str) -> dict:
    """Leg number -> PlantConfig from `default` or a TOML file:

        seed = 0                # start from the simulated rig's legs (default_leg_configs(seed))
        [all]                   # PlantConfig fields for every leg
        lead_slope_um_per_m = 9.0
        [leg.2]                 # fields for one leg
        reversal_um = 1.2
    """
    from drivers.sim.plant import PlantConfig, default_leg_configs

    if spec in ("", "default"):
        return {i + 1: c for i, c in enumerate(default_leg_configs(0))}
    path = Path(spec)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"--twin sim:{spec}: plant config file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({exc})") from None
    known = {f.name: f for f in fields(PlantConfig)}
    unknown = set(data) - {"seed", "legs", "all", "leg"}
    if unknown:
        raise InputError(f"{path}: unknown key(s) {sorted(unknown)} (known: seed, legs, [all], [leg.N])")
    seed = int(data.get("seed", 0))
    n_legs = int(data.get("legs", 6))
    cfgs = {i + 1: c for i, c in enumerate(default_leg_configs(seed, n_legs))}

    def apply(cfg, table, where):
        kw = {}
        for k, v in table.items():
            if k not in known:
                raise InputError(f"{path}: [{where}] {k}: not a plant parameter (known: {', '.join(sorted(known))})")
            if k == "enabled":
                v = frozenset(v)
            elif k == "longwave":
                v = tuple(tuple(float(a) for a in t) for t in v)
            elif k == "load_per_pass_n":
                v = tuple(float(a) for a in v)
            kw[k] = v
        try:
            return replace(cfg, **kw)
        except (TypeError, ValueError) as exc:
            raise InputError(f"{path}: [{where}]: {exc}") from None

    for leg in cfgs:
        cfgs[leg] = apply(cfgs[leg], data.get("all", {}), "all")
    for key, table in data.get("leg", {}).items():
        try:
            leg = int(key)
        except ValueError:
            raise InputError(f"{path}: [leg.{key}]: expected a leg number") from None
        cfgs[leg] = apply(cfgs.get(leg, PlantConfig()), table, f"leg.{key}")
    return cfgs


def plant_twin(cfgs: dict, description: str) -> ExternalTwin:
    """The plant's systematic error as a twin: position terms only (direction 0, temperature at
    the reference, no load, time 0), so backlash/thermal/load/drift are left in the gap."""
    from drivers.sim.plant import systematic_error_um

    def predict(leg, x_mm, direction):
        cfg = cfgs[leg]
        return systematic_error_um(cfg, x_mm, 0.0, cfg.temp_ref_c, 0.0, 0.0)

    return ExternalTwin(predict=predict, kind="sim", description=description, legs=frozenset(cfgs))


def sim_twin(spec: str) -> ExternalTwin:
    return plant_twin(_plant_configs(spec), f"simulated plant ({spec or 'default'})")
