"""Damaging valid JSON documents for the fuzz tests of the JSON readers (model, station table
store): a key deleted or a value replaced by any JSON value, at any depth."""

from __future__ import annotations

import copy

from hypothesis import strategies as st

json_value = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10, 10), st.integers(), st.sampled_from([10**400, -(10**30)]),
              st.floats(allow_nan=False, allow_infinity=False), st.sampled_from([1e308, -1e308, 5e-324, 0.0, -0.0]),
              st.text(max_size=10)),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=8,
)


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


def damaged_json(draw, doc: dict, max_rounds: int) -> dict:
    """A copy of `doc` with 1..max_rounds places (never the root) deleted (a dict's key) or
    replaced by a drawn JSON value."""
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, max_rounds))):
        where = draw(st.sampled_from([p for p in _paths(doc) if p]))
        parent = doc
        for k in where[:-1]:
            parent = parent[k]
        if draw(st.integers(0, 4)) == 0 and isinstance(parent, dict):
            del parent[where[-1]]
        else:
            parent[where[-1]] = draw(json_value)
    return doc
