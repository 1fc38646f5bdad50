"""A small TOML writer for the fuzz tests (tomllib reads only): any dict of str keys holding
str, int, float (inf and nan too), bool, lists and dicts becomes TOML text; and `damaged`, a
strategy damaging a valid document value by value, key by key, and cutting it short."""

from __future__ import annotations

import copy
import json
import math

from hypothesis import strategies as st


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


# -- damaging valid documents (the config, profile and import-map fuzz tests) --------------------

scalar = st.one_of(
    st.none(),  # None: the key is deleted
    st.booleans(), st.integers(-3, 70000), st.integers(), st.floats(),
    st.sampled_from([float("inf"), float("-inf"), float("nan"), 1e308, -0.0, 0, -1, 2**64, "", "sim", "tcp://127.0.0.1:502"]),
    st.text(max_size=12),
)
toml_value = st.recursive(scalar.filter(lambda v: v is not None),
                          lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3),
                          max_leaves=6)

def _leaves(node, prefix=()):
    if isinstance(node, dict):
        if prefix:
            yield prefix
        for k, v in node.items():
            yield from _leaves(v, prefix + (k,))
    elif isinstance(node, list):
        yield prefix
        for i, v in enumerate(node):
            yield from _leaves(v, prefix + (i,))
    else:
        yield prefix


@st.composite
def damaged(draw, doc: dict) -> bytes:
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(list(_leaves(doc))))
        parent = doc
        for k in where[:-1]:
            parent = parent[k]
        new = draw(st.one_of(scalar, toml_value))
        if new is None and isinstance(parent, dict):
            del parent[where[-1]]
        elif new is not None:
            parent[where[-1]] = new
    if draw(st.integers(0, 5)) == 0:  # a key or section nobody knows
        doc[draw(st.sampled_from(list(doc)))] = {draw(st.text(min_size=1, max_size=6)): draw(scalar.filter(lambda v: v is not None))}
    text = dumps(doc).encode()
    if draw(st.integers(0, 6)) == 0:
        text = text[: draw(st.integers(0, len(text)))]
    return text
