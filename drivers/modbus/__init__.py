"""Modbus servo drive: register-map profiles, client, and protocol helpers."""
