"""The operator process (the paper's "master"): joystick input, command publisher, view."""
