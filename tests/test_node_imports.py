"""What a node process loads (its memory, docs/performance.md *Imports and memory*): no pydantic (the
messages and the configuration are msgspec), no msgpack (msgspec encodes), no terminal UI, and not the
vehicle's or the collector's role code, nor the launcher's and the records' modules (with their standard
library: subprocess, tempfile, socket, random, gzip) that parsing a node's command line used to pull in."""

from __future__ import annotations

import subprocess
import sys

NODE_MODULES = (
    "netsetest.cli.main", "netsetest.cli.processes", "netsetest.runtime.security", "netsetest.runtime.processes",
    "netsetest.bus.zenoh_bus", "netsetest.roles.node",
)  # fmt: skip
NODE_ARGV = ["node", "paper6", "--id", "1"]
NEVER_IN_A_NODE = (
    "pydantic", "pydantic_core", "msgpack", "rich", "netsetest.roles.collector", "netsetest.roles.vehicle",
    "netsetest.runtime.launcher", "netsetest.runtime.forkserver", "netsetest.records.record", "netsetest.records.summary",
    "subprocess", "tempfile", "socket", "random", "gzip",
)  # fmt: skip


def test_node_process_loads_only_what_a_node_needs():
    code = (f"import sys\nfor m in {NODE_MODULES!r}: __import__(m)\n"
            f"sys.modules['netsetest.cli.main'].build_parser().parse_args({NODE_ARGV!r})\nprint(")  # fmt: skip
    code += f"sorted(set(sys.modules) & set({NEVER_IN_A_NODE!r})))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "[]", (out.stdout, out.stderr[-500:])
    # the check itself sees an import: the collector's module is there once imported
    code = code.replace("print(", "import netsetest.roles.collector\nprint(")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert "netsetest.roles.collector" in out.stdout, (out.stdout, out.stderr[-500:])
