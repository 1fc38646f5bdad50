"""What a model becomes on a drive or controller: compensation tables, every controller file format
(controllers/, LinuxCNC included), the applied table, push, verify and the audit log.
"""
