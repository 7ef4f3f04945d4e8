"""What a node process loads (its memory, docs/performance-history.md, *Imports and memory*): no pydantic (the
messages and the configuration are msgspec), no msgpack (msgspec encodes), no terminal UI, and not the
vehicle's or the collector's role code, nor the launcher's and the records' modules (with their standard
library: subprocess, tempfile, socket, random, gzip) that parsing a node's command line used to pull in."""

from __future__ import annotations

import os
import subprocess
import sys

NODE_MODULES = (
    "netsetest.cli.main",
    "netsetest.cli.processes",
    "netsetest.runtime.security",
    "netsetest.runtime.processes",
    "netsetest.bus.zenoh_bus",
    "netsetest.roles.node",
)
NODE_ARGV = ["node", "paper6", "--id", "1"]
NEVER_IN_A_NODE = (
    "pydantic",
    "pydantic_core",
    "msgpack",
    "rich",
    "netsetest.roles.collector",
    "netsetest.roles.vehicle",
    "netsetest.runtime.launcher",
    "netsetest.runtime.forkserver",
    "netsetest.records.record",
    "netsetest.records.summary",
    "subprocess",
    "tempfile",
    "socket",
    "random",
    "gzip",
    "_hashlib",  # OpenSSL's libcrypto, +3.5 MB: the state digest's BLAKE2 and the settings digest's SHA-256 are CPython's own
    "netsetest.analysis.calibrate",
    "netsetest.models.drive",
    "netsetest.estimator.zonotope_w_radius",  # the other methods load only in a node that runs them
    "netsetest.estimator.interval_althoff_rath",
    "netsetest.estimator.strip_althoff_rath",
    "netsetest.estimator.set_propagation_althoff_rath",
)


def test_node_process_loads_only_what_a_node_needs():
    # what a node does before its session: parse its command line and load its topology (the settings digest)
    code = f"import sys\nfor m in {NODE_MODULES!r}: __import__(m)\nsys.modules['netsetest.cli.main'].build_parser().parse_args({NODE_ARGV!r})\n"
    code += f"sys.modules['netsetest.runtime.rolespec'].ScenarioSpec({NODE_ARGV[1]!r}).load()\nprint("
    code += f"sorted(set(sys.modules) & set({NEVER_IN_A_NODE!r})))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "[]", (out.stdout, out.stderr[-500:])
    # the check itself sees an import: the collector's module is there once imported
    code = code.replace("print(", "import netsetest.roles.collector\nprint(")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert "netsetest.roles.collector" in out.stdout, (out.stdout, out.stderr[-500:])


def _run(code: str, **env: str) -> str:
    base = {k: v for k, v in os.environ.items() if k not in ("RUST_BACKTRACE", "RUST_LIB_BACKTRACE")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env={**base, **env})
    assert out.returncode == 0, out.stderr[-500:]
    return out.stdout.strip()


def test_zenoh_errors_capture_no_backtrace_unless_asked():
    """RUST_BACKTRACE=1 would make every Rust error value walk the stack (Zenoh makes one per link it
    closes: +1.2 MB of unwind tables resident at close); the bus turns that off, a user's choice wins."""
    code = "import os, netsetest.bus.zenoh_bus\nprint(os.environ.get('RUST_LIB_BACKTRACE'))"
    assert _run(code, RUST_BACKTRACE="1") == "0"
    assert _run(code, RUST_BACKTRACE="1", RUST_LIB_BACKTRACE="1") == "1"


def test_release_free_memory_returns_the_heaps_free_pages():
    code = (
        "from netsetest.runtime.processes import release_free_memory\n"
        "def rss_kb():\n"
        "    return next(int(l.split()[1]) for l in open('/proc/self/status') if l.startswith('VmRSS:'))\n"
        "blocks = [bytes(4000) for _ in range(10_000)]  # 40 MB from malloc (not Python's small-object arenas)\n"
        "keep = bytes(4000)  # above the freed blocks: the heap cannot shrink from its top\n"
        "del blocks\n"
        "before = rss_kb()\n"
        "release_free_memory()\n"
        "print(before - rss_kb())"
    )
    assert int(_run(code)) > 20_000  # kB: most of the 40 MB freed but still resident
