"""Session set-up: the role processes the tests start make their temporary directories (a run's
credentials, mode 0700) under one directory of this session, removed at its end, so a test that SIGKILLs a
run's parent (which then cannot clean up) leaves nothing behind in the system's /tmp."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True, scope="session")
def _children_tmpdir() -> Iterator[None]:
    root = tempfile.mkdtemp(prefix="netsetest-tests-")
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
