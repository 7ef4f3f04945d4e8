"""The bus's bound per key, on its own: what the roles' flow control (roles/flow.py) is sized by, importable without
the messages and the bus (a role spec's default window, runtime/rolespec.py, is read by every command line)."""

MAX_PER_KEY = 64  # a role handles ~1 message per key per step and pumps many times a step: more is a flood
