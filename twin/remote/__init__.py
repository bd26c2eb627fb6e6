"""Drive the twin from CoppeliaSim's own clients.

server.py serves the ZeroMQ remote API (protocol v2) over a Scene (session.py) whose sim.*
functions live in sim_api.py; protocol.py is the wire format; legacy.py offers the old simx*
calls over the same protocol; command.py holds the `twin serve` arguments. Importing this package
imports none of them (a legacy client program needs no pybullet).
"""
