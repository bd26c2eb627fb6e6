"""The data: Frame, Command, Event, their columns, the configuration and profiles, rotations."""
