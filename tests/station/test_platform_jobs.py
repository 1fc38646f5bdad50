"""The platform experiment's inputs and report live in station.platform_jobs, which both
`station platform` and the terminal UI's Platform page use (the UI imports no command module)."""

from station import platform_jobs
from station.commands import platform as platform_command


def test_the_command_and_the_ui_share_the_inputs_and_the_report():
    assert platform_command.load_errors is platform_jobs.load_errors
    assert platform_command.write_report is platform_jobs.write_report
