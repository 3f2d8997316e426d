"""Shared core of egc-teleop: wire contract, profiles, config, geometry and kinematics. No IO."""
