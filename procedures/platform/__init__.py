"""Gough-Stewart platform: geometry, kinematics, the paper's pose-error experiment, sensitivity.

See docs/platform.md for frames, pose convention and the experiment's rules.
"""
