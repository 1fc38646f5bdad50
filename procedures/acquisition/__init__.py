"""What moves a leg and measures it: sweep plans, the stop-and-go sweep, the on-the-fly passes, the
adaptive stopping rule, what the passes share, the measured points, a replay compared with its
recording.
"""
