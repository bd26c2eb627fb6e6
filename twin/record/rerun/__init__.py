"""Rerun: the .rrd writer, the scene it draws and the viewer (a view, made again from MCAP)."""
