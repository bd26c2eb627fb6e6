"""MCAP: the writer, readers, recovery and `twin info` (the source of truth)."""
