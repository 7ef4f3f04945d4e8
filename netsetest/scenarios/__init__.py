"""The bundled scenario files: ``topologies/*.toml`` and the node profiles ``nodes/*.toml``.

In a source checkout ``topologies`` and ``nodes`` here are symlinks to the top-level directories of the
same names (the one copy of the files); a wheel carries the files themselves (setuptools package data
follows the symlinks).  A topology's ``node_dir = "../nodes"`` resolves the same way in both layouts.
"""

from __future__ import annotations

from pathlib import Path

TOPOLOGY_DIR = Path(__file__).resolve().parent / "topologies"
TOPOLOGY_SUFFIX = ".toml"


def bundled_topologies() -> list[str]:
    """Names of the bundled topologies (file names without ``.toml``), sorted."""
    return sorted(p.stem for p in TOPOLOGY_DIR.glob(f"*{TOPOLOGY_SUFFIX}"))


def topology_help(what: str = "the topology") -> str:
    """The help text of an argument naming a topology: a file, or a bundled one, every name listed (from the files)."""
    return f"{what}: a file (e.g. topologies/paper6.toml) or the name of a bundled one: {', '.join(bundled_topologies())}"


def resolve_topology(arg: str | Path) -> Path:
    """``arg`` itself when it names an existing file, else the bundled topology of that name (``paper6``
    or ``paper6.toml``), else ``arg`` unchanged (the loader then reports the missing file)."""
    path = Path(arg)
    if path.exists() or path.name != str(arg):  # an existing file, or a path with directories
        return path
    bundled = TOPOLOGY_DIR / (path.name if path.suffix == TOPOLOGY_SUFFIX else path.name + TOPOLOGY_SUFFIX)
    return bundled if bundled.is_file() else path
