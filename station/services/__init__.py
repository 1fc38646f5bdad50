"""What a station does, for every front end: the composition root (wiring), config, the drive
lock, the jobs (sweep, replay, table, platform, report, diagnosis, analysis), twins, the rig
session (connection, lock discipline, rig actions, the checked move, session naming).

Plain Python: nothing here imports Textual or argparse (tests/test_layering.py), so the CLI
(station/commands), the TUI (station/tui) and any later front end call the same code."""
