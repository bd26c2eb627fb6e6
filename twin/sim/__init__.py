"""The simulation: the PyBullet world (the only pybullet import), the suction pad, the Twin."""
