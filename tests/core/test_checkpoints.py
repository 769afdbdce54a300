"""The reverse pass's checkpoint schedule: every iteration reversed once, in order,
within the memory budget, with the forward steps the schedule promises."""

from __future__ import annotations

import numpy as np
import pytest

from wbcgrade.core import GridGeometry
from wbcgrade.core._checkpoints import extra_steps
from wbcgrade.core.barycenter import BarycenterSolver, _Iterate
from wbcgrade.core.losses import get_loss


class _Counter:
    def __init__(self):
        self.states = self.records = self.steps = self.peak = 0
        self.reversed: list[int] = []

    def units(self) -> int:
        return self.states + 2 * self.records

    def note(self) -> None:
        self.peak = max(self.peak, self.units())


class _State:
    """Scalings entering iteration ``index`` (a stand-in: only its index matters)."""

    def __init__(self, counter: _Counter, index: int):
        self.counter, self.index = counter, index
        counter.states += 1
        counter.note()

    def __del__(self):
        self.counter.states -= 1


class _Record(_Iterate):
    def __init__(self, counter: _Counter, index: int):
        super().__init__(None, None, None, None, np.ones(3) / 3)
        self.counter, self.index = counter, index
        counter.records += 1
        counter.note()

    def __del__(self):
        self.counter.records -= 1


class _FakeBackend:
    """Counts forward steps and live states/records; checks the reverse order."""

    record_arrays = 2

    def __init__(self, counter: _Counter, n_iter: int):
        self.counter, self.n_iter = counter, n_iter

    def initial(self):
        return _State(self.counter, 0)

    def step(self, b, need_next=True, keep=True):
        self.counter.steps += 1
        it = _Iterate(None, None, None, None, np.ones(3) / 3)
        it.index = b.index + 1
        return (_State(self.counter, b.index + 1) if need_next else None), it

    def compact(self, it):
        return _Record(self.counter, it.index)

    def previous(self, record):
        return _State(self.counter, record.index)

    def sum_histograms(self, r):
        return np.ones(3)

    def adjoint(self, it, b_prev, g, r, need_r):
        assert it.index == b_prev.index + 1, "the iterate does not follow its scalings"
        self.counter.reversed.append(b_prev.index)
        return np.zeros(2), (np.zeros((2, 3)) if need_r else None)


@pytest.mark.parametrize("n_iter", [1, 2, 7, 23, 60])
@pytest.mark.parametrize("slots", [1, 2, 3, 5, 8, 13, 200])
def test_schedule_reverses_each_iteration_once_within_budget(n_iter, slots):
    counter = _Counter()
    state_bytes = 1000
    solver = BarycenterSolver(np.ones((2, 3)), GridGeometry(3, 0.1), n_iter,
                              checkpoint_bytes=slots * state_bytes)
    solver._slots = lambda state: slots
    backend = _FakeBackend(counter, n_iter)
    solver._gradient(backend, np.array([0.5, 0.5]), np.ones(3) / 3, get_loss("quadratic"))

    assert counter.reversed == list(range(n_iter - 1, -1, -1))
    assert counter.steps == n_iter + extra_steps(n_iter, slots, 2)
    # the budget, plus the initial scalings and the two being stepped between
    assert counter.peak <= slots + 3
    assert counter.states == 0 and counter.records == 0  # nothing left behind


@pytest.mark.slow
def test_schedule_costs_fall_with_memory_and_beat_bisection():
    costs = [extra_steps(60, s, 2) for s in range(0, 130)]
    assert all(a >= b for a, b in zip(costs, costs[1:]))
    assert costs[120] == 0  # every iteration recorded: nothing recomputed
    assert costs[0] == 60 * 61 // 2  # no slot: each iteration reached again from the start
    # 8 states (1.5 GB at 128^3, S = 10): bisection with a recomputed reverse step
    # cost ~2.9 passes; the schedule needs 1.8.
    assert costs[8] <= 1.8 * 60
