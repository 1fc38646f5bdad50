"""Hardware access: Modbus servo drives, serial laser interferometer, and their simulated and
replayed counterparts. Only `station/` (and tests) choose a concrete implementation."""
