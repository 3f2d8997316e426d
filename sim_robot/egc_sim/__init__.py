"""sim_robot: worlds, lidar, differential drive, collisions, scripted operators, episodes.

- ``worlds.load_world``: map_server maps, TOML geometric worlds, .npy grids, built-in names
  (``grid_world`` holds the ``World``; ``map_server``, ``shapes``, ``npy_grid``,
  ``random_field`` and ``worlds/`` build one).
- ``simulator.Simulator``: the robot in a world; ``lidar``, ``drive`` and ``collision`` hold
  its sensor, its base and its footprint test.
- ``operators``: scripted sticks; ``episodes.run_episode``: the headless loop, with the robot's
  controller passed in (the episode engine ``egc_experiments.episode`` wires the robot's pipeline).

Depends on ``egc_common`` only (DESIGN 2); time is passed in, never read.
"""
