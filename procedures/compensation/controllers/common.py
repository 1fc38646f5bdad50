"""What the controller formats share: file naming, atomic writing, refusing bad files."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from procedures.vocabulary import InputError
from procedures.io.numbers import parse_finite
from procedures.compensation.table import CompTable, LegTable, write_table_files, validate_table


class ControllerFileError(InputError):
    """A controller file is malformed; the message names file, line and field."""


def leg_paths(out: str | os.PathLike, legs: Iterable[int], suffix: str, stem: str = "leg{leg}") -> dict[int, Path]:
    """One file per leg: `OUT/<stem><suffix>` for a directory OUT, or `<name>_<stem><suffix>` beside
    OUT when OUT ends in `suffix` (case-insensitive)."""
    out = Path(out)
    if out.suffix.lower() == suffix.lower():
        return {leg: out.with_name(f"{out.stem}_{stem.format(leg=leg)}{out.suffix}") for leg in legs}
    return {leg: out / f"{stem.format(leg=leg)}{suffix}" for leg in legs}


def write_files(out: str | os.PathLike, texts: Mapping[Path, str], suffix: str) -> list[Path]:
    """Write every file or none (temporary files renamed into place); a directory OUT is created."""
    out = Path(out)
    if out.suffix.lower() != suffix.lower():
        out.mkdir(parents=True, exist_ok=True)
    return write_table_files(texts, ControllerFileError)


def checked(table: CompTable, spec, where) -> CompTable:
    """Validate against `spec` (points, corrections) before anything is written."""
    validate_table(table, spec, where=str(where))
    return table


def read_lines(path: str | os.PathLike) -> list[str]:
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8-sig").splitlines()
    except FileNotFoundError:
        raise ControllerFileError(f"{path}: no such file") from None
    except UnicodeDecodeError:
        raise ControllerFileError(f"{path}: not a text file") from None


def number(path, line_no: int, field: str, text: str) -> float:
    return parse_finite(text, f"{path}, line {line_no}, field {field}", ControllerFileError)


def interp_held(x, nodes, values) -> np.ndarray:
    """Linear between nodes, the first/last value held outside (every controller here does so)."""
    return np.interp(np.asarray(x, dtype=float), nodes, values)


def by_direction(x, direction) -> tuple[np.ndarray, np.ndarray]:
    """(x, direction) broadcast to one shape."""
    x = np.asarray(x, dtype=float)
    d = np.broadcast_to(np.asarray(direction), np.broadcast(x, np.asarray(direction)).shape)
    return np.broadcast_to(x, d.shape), d


def strictly_increasing(path, positions: list[float], lines: list[int], field: str) -> None:
    for i in range(1, len(positions)):
        if positions[i] <= positions[i - 1]:
            raise ControllerFileError(f"{path}, line {lines[i]}, field {field}: {positions[i]:g} is not above the "
                                      f"previous position {positions[i - 1]:g}; positions must increase")


def leg_errors_mm(t: LegTable) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions_mm, error_fwd_mm, error_rev_mm) of one leg's table."""
    return t.positions_mm, np.asarray(t.error_fwd_um) / 1000.0, np.asarray(t.error_rev_um) / 1000.0
