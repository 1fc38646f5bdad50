"""Calibration science and sequences. Imports only the interfaces of `drivers/`."""
