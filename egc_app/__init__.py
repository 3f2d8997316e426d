"""The ``egc-teleop`` console script: argument parsing and the wiring of the four packages.

This is the only package that may import more than one of egc_robot, egc_operator and egc_sim
(DESIGN 2: the demo and episode entry points wire them together).
"""
