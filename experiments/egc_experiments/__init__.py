"""The network lab (DESIGN 2, 10): link model, user-space link emulator, experiment runner.

Sits above ``egc_common``, ``egc_robot``, ``egc_operator`` and ``egc_sim`` and may wire them
together; nothing but the console script imports it.
"""
