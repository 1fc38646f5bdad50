"""Replay devices that answer from a recorded HDF5 session."""
