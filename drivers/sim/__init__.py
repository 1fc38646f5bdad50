"""Simulated leg rig: the plant (digital twin) behind real Modbus and serial protocols."""
