"""A small TOML writer for the fuzz tests (tomllib reads only): any dict of str keys holding
str, int, float (inf and nan too), bool, lists and dicts becomes TOML text."""

from __future__ import annotations

import json
import math


def _key(k: str) -> str:
    return _string(str(k))


def _string(s: str) -> str:
    # JSON's escapes are TOML's, except DEL, which TOML wants escaped and JSON leaves as is
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def dumps(doc: dict) -> str:
    """Top-level scalars first, then one [table] per dict and [[array]] per list of dicts."""
    lines, tables = [], []
    for k, v in doc.items():
        if isinstance(v, dict):
            tables.append((f"[{_key(k)}]", v))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            tables.extend((f"[[{_key(k)}]]", x) for x in v)
        else:
            lines.append(f"{_key(k)} = {value(v)}")
    for head, body in tables:
        lines.append(head)
        lines.extend(f"{_key(k)} = {value(x)}" for k, x in body.items())
    return "\n".join(lines) + "\n"
