"""The shared executor: one function over many items, here or in local worker processes."""

from __future__ import annotations

import os

import pytest

from wbcgrade._executor import Executor
from wbcgrade.errors import InputError

_SETUP_MARK = "WBCGRADE_TEST_EXECUTOR_SETUP"


def scaled(item: int, context: dict, offset: int = 0, seen: list | None = None):
    """item * context['factor'] + offset, with the worker's pid and its setup mark."""
    if seen is not None:
        seen.append(item)
    if item < 0:
        raise ValueError(f"negative item {item}")
    return item * context["factor"] + offset, os.getpid(), os.environ.get(_SETUP_MARK)


def mark_worker(context: dict) -> None:
    os.environ[_SETUP_MARK] = str(context["factor"])


def test_in_process_runs_in_order_with_the_local_callbacks():
    seen: list[int] = []
    with Executor({"factor": 3}) as executor:
        assert executor.in_process
        pairs = list(executor.map_unordered(scaled, [1, 2, 5], 10,
                                            local_kwargs={"seen": seen}))
    assert [item for item, _ in pairs] == [1, 2, 5] == seen
    assert [value for _, (value, pid, _) in pairs] == [13, 16, 25]
    assert {pid for _, (_, pid, _) in pairs} == {os.getpid()}


@pytest.mark.slow
def test_local_processes_get_the_context_once_and_the_setup():
    items = list(range(8))
    with Executor({"factor": 2}, jobs=2, worker_setup=mark_worker) as executor:
        assert not executor.in_process
        results = dict(executor.map_unordered(scaled, items, 1))
        assert sorted(results) == items
        assert all(results[i][0] == 2 * i + 1 for i in items)
        assert all(results[i][1] != os.getpid() for i in items)  # ran in the workers
        assert {results[i][2] for i in items} == {"2"}  # worker_setup ran with the context
        executor.set_context({"factor": 5})  # e.g. a series grade found after reading
        again = dict(executor.map_unordered(scaled, items))
    assert all(again[i][0] == 5 * i and again[i][2] == "5" for i in items)


@pytest.mark.slow
def test_an_error_in_a_worker_reaches_the_caller():
    with Executor({"factor": 1}, jobs=2) as executor, \
            pytest.raises(ValueError, match="negative item -1"):
        list(executor.map_unordered(scaled, [1, -1, 2]))


def test_a_missing_dask_is_a_one_line_error(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # as if not installed
    with pytest.raises(InputError, match=r"pip install 'wbcgrade\[dask\]'"), \
            Executor({}, scheduler="tcp://127.0.0.1:9"):
        pass


def dies_on_seven(item: int, context: dict) -> int:
    """item * factor, but the worker process is killed (as the OOM killer would) on 7."""
    import signal
    import time

    if item == 7:
        os.kill(os.getpid(), signal.SIGKILL)
    time.sleep(0.05)
    return item * context["factor"]


def test_a_dead_worker_loses_its_item_only():
    """A worker killed mid-item: that item is lost (``on_lost``), every other item is run
    (the pool is started again), and nothing is yielded twice."""
    with Executor({"factor": 2}, jobs=2) as executor:
        pairs = list(executor.map_unordered(dies_on_seven, range(12),
                                            on_lost=lambda item, why: ("lost", item)))
    assert sorted(item for item, _ in pairs) == list(range(12))
    assert dict(pairs) == {i: (("lost", 7) if i == 7 else 2 * i) for i in range(12)}


def test_more_jobs_than_a_pool_can_hold_is_an_option_error():
    """``-j 99999999999999999999`` raised OverflowError from the pool's semaphores."""
    from wbcgrade.errors import OptionError

    with pytest.raises(OptionError, match="jobs must be between 1 and"):
        Executor({}, jobs=99999999999999999999)
