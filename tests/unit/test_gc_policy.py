"""The garbage collector's policy for a run (netsetest/runtime/gc_policy.py): the young threshold raised inside, the
caller's restored after (also when the run raises), a higher one or 0 (the collector off) left alone."""

from __future__ import annotations

import gc
from collections.abc import Iterator

import pytest

from netsetest.runtime.gc_policy import YOUNG_THRESHOLD, long_run


@pytest.fixture
def thresholds() -> Iterator[None]:
    saved = gc.get_threshold()
    yield
    gc.set_threshold(*saved)


def test_raised_inside_and_restored_after(thresholds: None) -> None:
    gc.set_threshold(700, 10, 10)
    with long_run():
        assert gc.get_threshold() == (YOUNG_THRESHOLD, 10, 10)
    assert gc.get_threshold() == (700, 10, 10)

    @long_run()
    def fails() -> None:
        assert gc.get_threshold()[0] == YOUNG_THRESHOLD
        raise RuntimeError("the run failed")

    with pytest.raises(RuntimeError):
        fails()
    assert gc.get_threshold() == (700, 10, 10)


@pytest.mark.parametrize("mine", [0, 2 * YOUNG_THRESHOLD])
def test_a_callers_higher_threshold_or_none_is_kept(thresholds: None, mine: int) -> None:
    gc.set_threshold(mine, 10, 10)
    with long_run():
        assert gc.get_threshold() == (mine, 10, 10)
    assert gc.get_threshold() == (mine, 10, 10)
