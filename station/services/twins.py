"""Twins of the diagnosis built from files, the plant or the catalog, for both front ends
(`station diagnose --twin`, the terminal UI's Diagnosis page): MODEL.json, REFERENCE.h5,
sim:CONFIG.toml, sim:default or fleet:TYPE. The plant's twin is procedures.diagnosis.twin.plant_twin;
here its legs are read (a TOML file), and the fleet twin reads the catalog and the session files it
names."""

from __future__ import annotations

import tomllib
from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from procedures.diagnosis.reference_twin import twin_from_recording
from procedures.diagnosis.twin import ExternalTwin, plant_twin, twin_from_model
from procedures.vocabulary import InputError


def load_twin(spec: str, *, session=None, path=None, catalog=None):
    """The twin named by --twin: MODEL.json, REFERENCE.h5, sim:CONFIG.toml, sim:default or
    fleet:TYPE (which needs the `session` under diagnosis, read from `path`, and `catalog`: a
    callable returning the catalog engine to read)."""
    if spec.startswith("sim:"):
        return sim_twin(spec[4:])
    if spec.startswith("fleet:"):
        leg_type = spec[6:].strip()
        if not leg_type:
            raise InputError("--twin fleet:TYPE: name the leg type, e.g. fleet:HX-L300 (`station legs` lists them)")
        if session is None or catalog is None:
            raise InputError(f"--twin {spec}: the fleet twin needs the session under diagnosis and the catalog")
        return fleet_twin(leg_type, session, path, catalog())
    path = Path(spec)
    if not path.exists():
        raise InputError(f"--twin {spec}: no such file (give MODEL.json, REFERENCE.h5 or sim:CONFIG.toml)")
    if path.suffix.lower() == ".json":
        from procedures.fit.model_io import load_model

        return twin_from_model(load_model(path), str(path))
    if path.suffix.lower() in (".h5", ".hdf5"):
        from procedures.metrology.thermal import normalise_session
        from procedures.io.recording.reader import read_session

        ref = read_session(path)
        n = normalise_session(ref.points, ref.station_config)
        normalised = n.points[np.isin(n.points["leg"], n.normalised)] if n.normalised else None
        return twin_from_recording(ref.points, str(path), normalised)
    raise InputError(f"--twin {spec}: unknown kind of twin (expected .json, .h5 or sim:CONFIG.toml)")


def _plant_configs(spec: str) -> dict:
    """Leg number -> PlantConfig from `default` or a TOML file:

        seed = 0                # start from the simulated rig's legs (default_leg_configs(seed))
        [all]                   # PlantConfig fields for every leg
        lead_slope_um_per_m = 9.0
        [leg.2]                 # fields for one leg
        reversal_um = 1.2
    """
    from drivers.plant.leg import PlantConfig, default_leg_configs

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


def sim_twin(spec: str) -> ExternalTwin:
    return plant_twin(_plant_configs(spec), f"simulated plant ({spec or 'default'})")


def fleet_twin(leg_type: str, session, path, engine):
    """The legs of type `leg_type` in the catalog as the twin of each leg of `session`: per leg,
    the last completed session of every other serial of that type (the session under diagnosis
    and the leg's own serial left out), read from the files the catalog names. Normalised to
    20 degC when this session and every sibling carry the material temperature, else raw.
    InputError when a leg has fewer than 3 siblings (procedures/diagnosis/fleet.py)."""
    from procedures.diagnosis.fleet import MIN_SIBLINGS, content_key, error_map, fleet_leg, independent_maps
    from procedures.diagnosis.fleet import fleet_twin as make_twin
    from procedures.metrology.thermal import normalise_session
    from procedures.io.recording.reader import read_session
    from station.catalog.fleet import completed_sessions_of_type, latest_per_serial
    from station.catalog.identity_reader import legs_of
    from station.catalog.readers import session_identity

    ids = legs_of(session_identity(path)) if path is not None else {}
    for leg, info in sorted(ids.items()):
        if info.get("leg_type") and info["leg_type"] != leg_type:
            raise InputError(f"--twin fleet:{leg_type}: leg {leg} of {path} is serial {info['serial']} of type "
                             f"{info['leg_type']}, not {leg_type}; use --twin fleet:{info['leg_type']}")
    rows = [r for r in completed_sessions_of_type(engine, leg_type) if r.sha256 != session.sha256]
    latest = latest_per_serial(rows)
    skipped: list[str] = []
    raw_maps, norm_maps = {}, {}
    files: dict[str, tuple] = {}
    for serial, r in latest.items():
        if r.path not in files:
            try:
                s = read_session(r.path)
            except (InputError, OSError) as exc:
                files[r.path] = (None, None, f"{r.path}: {exc}")
            else:
                why = None if s.sha256 == r.sha256 else f"{r.path}: changed since the catalog indexed it"
                files[r.path] = (s, normalise_session(s.points, s.station_config), why)
        s, n, why = files[r.path]
        if why:
            skipped.append(f"{serial} ({why})")
            continue
        raw_maps[serial] = error_map(s.points, r.leg)
        if r.leg in n.normalised:
            norm_maps[serial] = error_map(n.points, r.leg)
    # siblings that are the same measurement under another name (by content, issue 35): counted once,
    # or the spread shrinks and a leg lies "-352 sigma" off three copies of one session
    raw_maps, duplicates = independent_maps(raw_maps)
    norm_maps = {k: v for k, v in norm_maps.items() if k not in duplicates}
    here = normalise_session(session.points, session.station_config)
    legs = [int(v) for v in np.unique(session.points["leg"])]
    normalised = all(leg in here.normalised for leg in legs) and len(norm_maps) == len(raw_maps)
    maps = norm_maps if normalised else raw_maps
    points = here.points if normalised else session.points
    fleet = {}
    for leg in legs:
        own = (ids.get(leg) or {}).get("serial")
        mine = content_key(error_map(session.points, leg))
        same_as_this = sorted(k for k, v in raw_maps.items() if k != own and content_key(v) == mine)
        for k in same_as_this:  # this very measurement under another serial: not a sibling
            duplicates[k] = f"this session (leg {leg})"
        siblings = {k: v for k, v in maps.items() if k != own and k not in same_as_this}
        if len(siblings) < MIN_SIBLINGS:
            raise InputError(f"--twin fleet:{leg_type}: {len(siblings)} sibling leg(s) of type {leg_type} in the catalog "
                             f"for leg {leg}" + (f" (serial {own} and this session left out)" if own else "")
                             + f"; at least {MIN_SIBLINGS} needed" + (f"; unreadable: {'; '.join(skipped)}" if skipped else "")
                             + (f"; the same measurement as another counted once: {_dup_text(duplicates)}"
                                if duplicates else ""))
        x = points["target_mm"][points["leg"] == leg]
        fleet[leg] = fleet_leg(x, siblings)
    n_sib = sorted({fl.n for fl in fleet.values()})
    basis = "normalised to 20 degC" if normalised else "raw (not every session carries the material temperature)"
    description = (f"fleet of type {leg_type}: mean error map per direction of {'/'.join(map(str, n_sib))} sibling legs "
                   f"(their last completed sessions), {basis}")
    if duplicates:
        description += f"; duplicates counted once: {_dup_text(duplicates)}"
    info = {"leg_type": leg_type, "basis": "normalised" if normalised else "raw", "skipped": skipped,
            "siblings": {str(leg): fl.serials for leg, fl in fleet.items()}, "duplicates": duplicates}
    return make_twin(fleet, leg_type, description, normalised, info)


def _dup_text(duplicates: dict[str, str]) -> str:
    return ", ".join(f"{k} (same as {v})" for k, v in sorted(duplicates.items()))
