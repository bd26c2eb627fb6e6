"""Keyboard teleoperation: the session, its terminal screen and the key maps."""
