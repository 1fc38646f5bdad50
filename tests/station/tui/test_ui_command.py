"""`station ui` argument handling (the app itself is covered by the Pilot tests)."""

from __future__ import annotations

from station.cli import build_parser, main


def test_station_without_arguments_starts_the_ui_command():
    parser = build_parser()
    assert "ui" in parser._subparsers._group_actions[0].choices  # cli.main([]) runs "ui" when it exists


def test_bad_arguments_are_one_line_errors(tmp_path, capsys):
    assert main(["ui", "--replay", str(tmp_path / "none.h5")]) == 2
    assert main(["ui", "--config", str(tmp_path / "none.toml")]) == 2
    assert main(["ui", "--time-scale", "-1"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [
        f"station ui: error: argument --replay: {tmp_path / 'none.h5'}: no such file or directory; give a session file "
        "(FILE.h5); see `station ui --help`",
        f"station ui: error: argument --config: {tmp_path / 'none.toml'}: no such file or directory; give a station "
        "config (TOML text); see `station ui --help`",
        "station ui: error: argument --time-scale: '-1' is outside 0 .. 1000; give a time scale as a number "
        "(0 .. 1000), e.g. 0.1; see `station ui --help`",
    ]
