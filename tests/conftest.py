"""Session set-up: the role processes the tests start make their temporary directories (a run's
credentials, mode 0700) under one directory of this session, removed at its end, so a test that SIGKILLs a
run's parent (which then cannot clean up) leaves nothing behind in the system's /tmp."""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from fuzzing import THOROUGH, THOROUGH_EXAMPLES
from hypothesis import HealthCheck, settings

from netsetest import polygon

# the Zenoh tests' fixtures (``procs``: every process a test starts is stopped after it), for every module
pytest_plugins = ["zenoh_helpers"]
LAYERS = ("unit", "inmemory", "process")  # tests/<layer>/: each test is marked with its folder's layer

# HYPOTHESIS_PROFILE=thorough: the long run of the cuts' and the polygon operations' properties (DEVELOPERS.md), random
# examples, no database; the tests that set their own count take it from fuzzing.examples
settings.register_profile(
    THOROUGH,
    max_examples=THOROUGH_EXAMPLES,
    derandomize=False,
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))

# The polygon operations' backend (netsetest/polygon.py): NETSETEST_POLYGON's if set (the whole suite compiled:
# NETSETEST_POLYGON=compiled pytest), else plain Python; the polygon tests run on both (the polygon_backend fixture)


@pytest.fixture(scope="module", params=polygon.BACKENDS)
def polygon_backend(request: pytest.FixtureRequest) -> Iterator[str]:
    """Each of the polygon operations' backends in turn (module-scoped: Hypothesis's tests take no function-scoped
    fixture); the compiled one skipped where numba is not installed (the ``fast`` extra)."""
    if request.param == "compiled":
        pytest.importorskip("numba", reason="the compiled polygon backend needs numba (the fast extra)")
    before = polygon._use(request.param)
    yield request.param
    polygon._use(before)


# A shell starting pytest in the background without job control (`cmd &` in a script, nohup) hands it SIGINT
# ignored, and an ignored signal stays ignored across exec: every `netsetest run` a test starts would then
# shrug off the Ctrl-C the shutdown tests send (exit 0 or a timeout). The tests are about netsetest's handling,
# not the launcher's, so they restore the default disposition for the processes they start.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


# modules that read the same recorded runs (run_helpers.shared_run, cached per worker): one worker runs them
SHARED_RUN_MODULES = frozenset({"test_fdi.py", "test_sector.py", "test_containment.py", "test_headline.py"})


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist reads the groups
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test with its layer (its folder), so that nothing goes unmarked; a process test also
    counts as ``zenoh`` (it may open sessions or spawn roles). A test outside the layers is an error.
    Each module is one pytest-xdist group (``--dist loadgroup``: a module's fixtures made once), the
    modules of :data:`SHARED_RUN_MODULES` one group together (their runs made once)."""
    for item in items:
        layer = item.path.parent.name
        if layer not in LAYERS:
            raise pytest.UsageError(f"{item.nodeid}: every test lives in tests/unit, tests/inmemory or tests/process")
        item.add_marker(layer)
        if layer == "process":
            item.add_marker("zenoh")
        group = "shared-runs" if item.path.name in SHARED_RUN_MODULES else f"{layer}/{item.path.name}"
        item.add_marker(pytest.mark.xdist_group(group))


SESSION_PREFIX = "netsetest-tests-"  # one per session (with pytest-xdist: one per worker), removed at its end


@pytest.fixture(autouse=True, scope="session")
def _children_tmpdir() -> Iterator[None]:
    root = tempfile.mkdtemp(prefix=SESSION_PREFIX)
    previous = os.environ.get("TMPDIR")
    os.environ["TMPDIR"] = root  # read by every child process's tempfile at start
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop("TMPDIR", None)
        else:
            os.environ["TMPDIR"] = previous
        shutil.rmtree(root, ignore_errors=True)
    assert not os.path.exists(root), f"the session's temporary directory {root} could not be removed"


# ---------------------------------------------------------------- nothing left behind

SYSTEM_TMP = os.environ.get("TMPDIR", "/tmp")  # before the session fixture points TMPDIR elsewhere
OURS = ("netsetest", "nsbench", "nsattack")  # the prefixes of every temporary file or directory the package makes
_before: set[str] = set()


def _ours() -> set[str]:
    """Our temporary entries in the system's directory; a session's own directory (any session's, or any
    xdist worker's: each removes its own at its end, checked above) is not one."""
    try:
        return {n for n in os.listdir(SYSTEM_TMP) if n.startswith(OURS) and not n.startswith(SESSION_PREFIX)}
    except OSError:
        return set()


def _in_use(names: list[str]) -> set[str]:
    """Those of ``names`` a live process names on its command line, works in or holds open: another job's
    (a benchmark running beside the tests), since when this runs every process of the session has ended."""
    paths = {n: os.path.join(SYSTEM_TMP, n) for n in names}
    used: set[str] = set()
    for pid in filter(str.isdigit, os.listdir("/proc")):
        refs = []
        for what in ("cmdline", "cwd", *(f"fd/{fd}" for fd in _listdir(f"/proc/{pid}/fd"))):
            try:
                link = f"/proc/{pid}/{what}"
                refs.append(Path(link).read_bytes().decode(errors="replace") if what == "cmdline" else os.readlink(link))
            except OSError:  # gone, or not ours to read
                pass
        used.update(n for n, path in paths.items() if any(path in r for r in refs))
    return used


def _listdir(path: str) -> list[str]:
    try:
        return os.listdir(path)
    except OSError:
        return []


def _is_xdist_worker(config: pytest.Config) -> bool:
    return hasattr(config, "workerinput")  # pytest-xdist: the controller checks once, after every worker ended


def pytest_sessionstart(session: pytest.Session) -> None:
    if not _is_xdist_worker(session.config):
        _before.update(_ours())


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Fail the run if a test left a temporary file or directory of ours (a run's private keys) in the
    system's temporary directory: every test works in tmp_path or the session's directory. Under pytest-xdist
    the controller checks, after every worker has ended (a worker's own check would see the others' files). An
    entry a live process still uses is another job's (the machine may be shared), not one left behind."""
    if _is_xdist_worker(session.config):
        return
    left = sorted(_ours() - _before)
    left = [n for n in left if n not in _in_use(left)] if left else left
    if left:
        session.config.pluginmanager.get_plugin("terminalreporter").write_line(f"tests left behind in {SYSTEM_TMP}: {', '.join(left)}", red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
