"""What a node process loads (its memory, docs/performance.md *Imports and memory*): no pydantic (the
messages and the configuration are msgspec), no msgpack (msgspec encodes), no terminal UI, and not the
vehicle's or the collector's role code."""

from __future__ import annotations

import subprocess
import sys

NODE_MODULES = (
    "netsetest.cli.main", "netsetest.cli.processes", "netsetest.runtime.security", "netsetest.runtime.processes",
    "netsetest.bus.zenoh_bus", "netsetest.roles.node",
)  # fmt: skip
NEVER_IN_A_NODE = ("pydantic", "pydantic_core", "msgpack", "rich", "netsetest.roles.collector", "netsetest.roles.vehicle")


def test_node_process_loads_no_pydantic_and_no_other_roles():
    code = f"import sys\nfor m in {NODE_MODULES!r}: __import__(m)\nprint(sorted(set(sys.modules) & set({NEVER_IN_A_NODE!r})))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "[]", (out.stdout, out.stderr[-500:])
    # the check itself sees an import: the collector's module is there once imported
    code = code.replace("print(", "import netsetest.roles.collector\nprint(")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert "netsetest.roles.collector" in out.stdout, (out.stdout, out.stderr[-500:])
