"""Which states the reverse pass keeps and which it recomputes: a pure schedule.

The reverse pass of L unrolled iterations visits them last to first and needs,
for iteration l, what its forward step computed (a *record*: ``K b`` and
``phi``, :attr:`iterate_slots` states' worth) or at least the scalings ``b``
entering it (a *checkpoint*, one state), from which the step is recomputed.
Memory holds ``slots`` states. The schedule that does the fewest forward steps
within that memory is found by dynamic programming over segments (in the
spirit of binomial checkpointing, "Revolve", with the extra option of
recording a short tail of iterations outright):

- a segment of ``n`` iterations whose start is held can be *recorded* when
  ``n * iterate_slots <= slots``: ``n`` forward steps, then no step at all in
  reverse;
- or *split* after ``m`` iterations: advance ``m`` steps, keep that checkpoint
  (one slot), reverse the right part with one slot less, drop it, and reverse
  the left part with all the slots;
- a single iteration with no room for its record is recomputed in its
  reverse step (one forward step);
- with no slot at all, each iteration is reached again from the segment's
  start (a *sweep*, ``n (n + 1) / 2`` steps).

The first forward pass (which must run anyway, for ``P_L``) passes through
the whole range, so along its right spine the checkpoints and the tail's
records are free: :func:`top_plan` accounts for that.
"""

from __future__ import annotations

from functools import lru_cache

__all__ = ["RECORD", "RECOMPUTE", "SWEEP", "segment_plan", "top_plan", "extra_steps"]

#: Plan of a segment: record all of its iterations.
RECORD = 0
#: Plan of a one-iteration segment: recompute the step in reverse.
RECOMPUTE = -1
#: Plan of a segment with no free slot: reach each iteration again from the start.
SWEEP = -2

_NEVER = 1 << 60


@lru_cache(maxsize=64)
def _tables(n_max: int, slots: int, iterate_slots: int):
    """Cost and choice tables for segments of 1..n_max iterations and 0..slots free slots.

    ``cost[n][s]``: forward steps to reverse a segment of ``n`` from its held
    start; ``top[n][s]``: the same when the first forward pass has just gone
    through it (its checkpoints and records are free). Choices: ``RECORD``,
    ``RECOMPUTE``, ``SWEEP`` or the split length ``m`` (1..n-1).
    """
    cost = [[0] * (slots + 1) for _ in range(n_max + 1)]
    choice = [[RECOMPUTE] * (slots + 1) for _ in range(n_max + 1)]
    top = [[0] * (slots + 1) for _ in range(n_max + 1)]
    top_choice = [[RECOMPUTE] * (slots + 1) for _ in range(n_max + 1)]
    for n in range(1, n_max + 1):
        for s in range(slots + 1):
            if n * iterate_slots <= s:
                cost[n][s], choice[n][s] = n, RECORD
                top[n][s], top_choice[n][s] = 0, RECORD
                continue
            if n == 1:
                cost[n][s], choice[n][s] = 1, RECOMPUTE
                top[n][s], top_choice[n][s] = 1, RECOMPUTE
                continue
            if s == 0:
                sweep = n * (n + 1) // 2
                cost[n][s], choice[n][s] = sweep, SWEEP
                top[n][s], top_choice[n][s] = sweep, SWEEP
                continue
            best, best_m, best_top, best_top_m = _NEVER, RECOMPUTE, _NEVER, RECOMPUTE
            for m in range(1, n):
                right, left = cost[n - m][s - 1], cost[m][s]
                if m + right + left < best:
                    best, best_m = m + right + left, m
                right_top = top[n - m][s - 1]
                if right_top + left < best_top:
                    best_top, best_top_m = right_top + left, m
            cost[n][s], choice[n][s] = best, best_m
            top[n][s], top_choice[n][s] = best_top, best_top_m
    return cost, choice, top, top_choice


def _bounded(n: int, slots: int, iterate_slots: int) -> int:
    """Slots beyond ``n * iterate_slots`` change nothing; cap them (smaller tables)."""
    if n < 1 or iterate_slots < 1:
        raise ValueError("a schedule needs at least one iteration and positive record size")
    return max(0, min(int(slots), n * iterate_slots))


def segment_plan(n: int, slots: int, iterate_slots: int) -> int:
    """How to reverse ``n`` iterations from a held start with ``slots`` free: a choice."""
    s = _bounded(n, slots, iterate_slots)
    return _tables(n, s, iterate_slots)[1][n][s]


def top_plan(n: int, slots: int, iterate_slots: int) -> int:
    """Like :func:`segment_plan` for a segment the first forward pass has just run through."""
    s = _bounded(n, slots, iterate_slots)
    return _tables(n, s, iterate_slots)[3][n][s]


def extra_steps(n: int, slots: int, iterate_slots: int) -> int:
    """Forward steps the reverse pass of ``n`` iterations recomputes (beyond the first pass)."""
    s = _bounded(n, slots, iterate_slots)
    return _tables(n, s, iterate_slots)[2][n][s]
