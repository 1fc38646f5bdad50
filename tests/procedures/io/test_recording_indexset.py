"""The writer's record of the indices in a file (procedures/io/recording/writer.py `_IndexSet`): a
bitmap, so a day-long session does not grow the station's memory (bench/bench_soak.py), with the
semantics of the set it replaced."""

from __future__ import annotations

import random

from procedures.io.recording.writer import _IndexSet


def test_the_index_set_behaves_as_a_set_of_its_indices():
    rng = random.Random(3)
    values = [rng.randrange(0, 300_000) for _ in range(5000)] + [0, 7, 8, 1 << 24, (1 << 40) + 3]
    s = _IndexSet(values[:2500])
    s.update(values[2500:])
    ref = set(values)
    assert len(s) == len(ref) and set(s) == ref
    probe = [rng.randrange(0, 400_000) for _ in range(5000)] + [1 << 24, (1 << 24) + 1, -1]
    assert all((i in s) == (i in ref) for i in probe)
    assert s.intersection(probe) == ref.intersection(probe)
    assert list(s) == sorted(ref)  # ascending, the large ones last


def test_the_index_set_stays_small_for_a_day_long_session():
    s = _IndexSet(range(200_000))
    assert len(s._bits) <= 64 * 1024 and not s._large  # noqa: SLF001 - one bit a point, not a Python int
