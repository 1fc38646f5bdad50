"""Files in and out: session files (recording/), the interchange CSV and import maps, the ranges values
read must lie in, the replay comparison, the all-or-nothing writer, the finite-number reader.
"""
