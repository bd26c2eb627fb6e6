"""Comparing two runs in physical units (numpy only: no pybullet, mcap or rerun)."""
