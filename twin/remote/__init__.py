"""Drive the twin from CoppeliaSim's own clients.

server.py serves the ZeroMQ remote API (protocol v2) over a Scene (session.py) whose sim.*
functions live in sim_api.py; protocol.py is the wire format; intake.py bounds what one connection
can make the server buffer; legacy.py offers the old simx* calls over the same protocol; the
`twin serve` arguments are in twin/cli/serve.py. Importing this package imports none of them (a
legacy client program needs no pybullet, `twin --help` no zmq).
"""

DEFAULT_STEP_GRACE_S = 10.0  # a stepping client silent this long no longer holds the others back
STEP_GRACE_RANGE_S = (0.01, 3600.0)  # what --step-grace accepts, seconds
