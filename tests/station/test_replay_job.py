"""The replay job lives with the other jobs both front ends start (station.services.jobs), the comparison
with the recording in procedures.acquisition.replay_compare; `station replay` uses the same objects."""

import argparse

import pytest

from procedures.vocabulary import InputError
from station.services import jobs
from station.commands import replay as replay_command
from tests.tooling import defines, imported_names


def test_the_command_uses_the_shared_job_and_comparison():
    # by its imports (inside run(): `station replay --help` loads neither), and no copy of its own
    assert imported_names("station.commands.replay")["prepare_replay"] == "station.services.replay_job.prepare_replay"
    assert imported_names("station.services.replay_job")["replay_and_compare"] == "station.services.jobs.replay_and_compare"
    assert imported_names("station.services.jobs")["compare_sessions"] == "procedures.acquisition.replay_compare.compare_sessions"
    for name in ("replay_and_compare", "replay_sweep", "retry_policy_of", "compare_sessions", "Comparison"):
        assert not defines("station.commands.replay", name)


def test_one_speed_parser_for_both_front_ends_with_the_same_message():
    assert jobs.parse_speed("max") is None and jobs.parse_speed(" MAX ") is None and jobs.parse_speed("fastest") is None
    assert jobs.parse_speed("1") == 1.0 and jobs.parse_speed("2.5") == 2.5
    tail = "give a speed factor as a number or 'max' or 'fastest' or 'inf' (>0 .. 1000000), e.g. 10"
    for bad, message in [("fast", f"'fast' is not a number; {tail}"),
                         ("0", f"'0' is outside >0 .. 1000000; {tail}"),
                         ("nan", f"'nan' is not a number; {tail}"),
                         ("1,5", "'1,5': a comma is not a decimal separator here (it could mean 1.5 or 15); write 1.5 "
                                 "with a decimal point")]:
        with pytest.raises(InputError) as ui:  # what the Replay screen shows
            jobs.parse_speed(bad)
        with pytest.raises(argparse.ArgumentTypeError) as cli:  # what argparse prints for --speed
            replay_command.parse_speed(bad)
        assert str(ui.value) == str(cli.value) == message
