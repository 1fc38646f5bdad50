"""Simulated leg rig: the plant (drivers/plant, the digital twin) behind real Modbus and serial protocols."""
