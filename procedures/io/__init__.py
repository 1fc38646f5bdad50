"""Files in and out: session files (recording/), the interchange CSV and import maps, the ranges values
read must lie in, the all-or-nothing writer of outputs, the finite-number reader.
"""
