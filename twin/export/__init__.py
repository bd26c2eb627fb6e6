"""Data out: a recording's tables as Parquet or CSV, and recordings as LeRobot v3.0 datasets."""
