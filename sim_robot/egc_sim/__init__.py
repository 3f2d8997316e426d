"""sim_robot: worlds, lidar, differential drive, collisions, scripted operators, episodes."""
