"""Compensation tables in the formats of motion controllers, and the rule each applies.

One module per controller, each with a writer (a procedures.compensation.table.CompTable to the controller's
file(s), validated first, written atomically) and a reader (`load`) that returns an object whose
`applied_mm(position_mm, direction)` is the correction the controller adds to the commanded
position there (mm; +1 = reached while the position increases). A table that cancels the
error e(x) (measured minus commanded, um) gives applied_mm = -e(x)/1000. docs/controllers.md
cites each controller's documentation and states its sign convention.
"""

from __future__ import annotations

import importlib
from types import ModuleType

FORMATS = ("siemens840d", "heidenhain", "twincat", "ecmc")
"""The controller formats beside LinuxCNC (procedures.compensation.controllers.linuxcnc; `station table
--format linuxcnc` keeps its own options)."""

HINTS = {
    "siemens840d": "SINUMERIK: load the init program (NC tables; MD18342 $MN_MM_CEC_MAX_POINTS >= points, "
                   "MD32710 $MA_CEC_ENABLE = 1, or MD32700 ENC_COMP_ENABLE for $AA_ENC_COMP); axis AX<leg>",
    "heidenhain": "TNC: copy leg<N>.COM to the control, enter it in the .CMA table's axis column and activate the line",
    "twincat": "TwinCAT CNC: name achskw<N>.lis in the start-up list, lr_param.ssfk = 1 (P-AXIS-00175)",
    "ecmc": "ecmc: loadLUTFile.cmd FILE=leg<N>.lut, then the encoder's lookuptable enable (scale 1)",
}


def module(name: str) -> ModuleType:
    """The module of a controller format (FORMATS or linuxcnc)."""
    if name not in FORMATS + ("linuxcnc",):
        raise ValueError(f"unknown controller format {name!r}")
    return importlib.import_module(f"procedures.compensation.controllers.{name}")
