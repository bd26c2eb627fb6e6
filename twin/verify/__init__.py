"""Replay, golden checks, the pytest plugin and the diff view: run the twin again and compare."""
