"""The robot's geometry: URDF, kinematics (the only FK/IK), profile files."""
