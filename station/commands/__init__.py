"""One module per `station` sub-command. Each defines:

    NAME: str                      the sub-command name
    HELP: str                      one line for `station --help`
    def add_arguments(p): ...      argparse arguments
    def run(args) -> int: ...      exit code; raise InputError/DriverError for clear messages

`station.cli` discovers the modules here, so adding a command is adding a file.
"""
