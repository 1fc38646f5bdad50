"""The application: command line, terminal UI, configuration and wiring (composition root)."""

__version__ = "0.1.0"
