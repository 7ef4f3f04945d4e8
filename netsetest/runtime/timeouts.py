"""Default timeouts of the role processes, shared by the CLI's options and the launcher.

A module of its own: every ``netsetest`` command builds every parser, and a role process must not load
the launcher (subprocess, tempfile, socket, ...) for three numbers (memory: docs/performance-history.md).
"""

START_TIMEOUT_S = 60.0  # the vehicle's default wait for every role to be ready
NODE_TIMEOUT_S = 10.0  # lockstep: a node silent this long is declared dead by the vehicle
NEIGHBOUR_TIMEOUT_S = 5.0  # lockstep: how long a node waits for a neighbour's message
STALL_LIMIT_S = 600.0  # how long a role may not run (stopped, a swapping machine) and the run go on: every session's
# Zenoh lease (a session silent longer is closed, with what was in flight to it) and the vehicle's wait for the collector
READING_WAIT = 0.25  # real time: how long (in sampling periods) a node waits for the references' readings of its step
READING_POLL = 0.02  # real time: how often (in sampling periods) a node waiting for readings looks for them
