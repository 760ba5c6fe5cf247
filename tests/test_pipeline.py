"""The threads' schedule of a batch's chunks (ddmr_cli/engine/pipeline.py): every task once, each when its inputs are
ready and its buffers free, progress in order, a failure raised, in one thread or several."""

import random
import threading
import time

import pytest

from ddmr_cli.engine.pipeline import run_chunks


def _record(n_chunks, n_blocks, parts, threads, slots, after_all=None, seed=0):
    """Run the schedule on tasks that sleep a random moment; every start and end as a tick of one shared clock."""
    clock, lock, events = [0], threading.Lock(), []
    rng = random.Random(seed)
    pauses = {key: rng.uniform(0.0, 0.002) for key in
              [("step", i, b) for i in range(n_chunks) for b in range(n_blocks)]
              + [("reduce", i, p) for i in range(n_chunks) for p in range(parts[i])]}

    def task(kind):
        def run(i, index):
            with lock:
                clock[0] += 1
                start = clock[0]
            time.sleep(pauses[(kind, i, index)])
            with lock:
                clock[0] += 1
                events.append((kind, i, index, start, clock[0]))
        return run

    done = []

    def report(i):
        with lock:
            clock[0] += 1
            done.append((i, clock[0]))

    run_chunks(n_chunks, n_blocks, task("step"), parts, task("reduce"), threads, slots=slots, after_all=after_all,
               done=report)
    return events, done


@pytest.mark.parametrize("threads, slots", [(1, 1), (1, 2), (2, 1), (2, 2), (3, 2), (3, 3)])
def test_every_task_runs_once_after_its_inputs_and_with_its_buffer_free(threads, slots):
    n_chunks, n_blocks = 7, 5
    parts = [2, 0, 3, 1, 2, 2, 1]  # a chunk with no grid points (no reduction) among them
    after_all = [False] * (n_chunks - 1) + [True]  # the shorter last chunk
    events, done = _record(n_chunks, n_blocks, parts, threads, slots, after_all, seed=threads * 10 + slots)
    steps = {(i, b): (s, e) for kind, i, b, s, e in events if kind == "step"}
    reduces = {(i, p): (s, e) for kind, i, p, s, e in events if kind == "reduce"}
    assert len(events) == len(steps) + len(reduces)  # no task twice
    assert set(steps) == {(i, b) for i in range(n_chunks) for b in range(n_blocks)}
    assert set(reduces) == {(i, p) for i in range(n_chunks) for p in range(parts[i])}

    def finished(i):  # the tick chunk i's last task ended
        return max([steps[i, b][1] for b in range(n_blocks)] + [reduces[i, p][1] for p in range(parts[i])])

    for (i, b), (start, _) in steps.items():
        if i > 0:
            assert start > steps[i - 1, b][1]  # a block's chunks in order
        if i >= slots:
            assert start > finished(i - slots)  # its band buffer was reduced and is free
        if after_all[i]:
            assert start > max(steps[i - 1, other][1] for other in range(n_blocks))
    for (i, p), (start, _) in reduces.items():
        assert start > max(steps[i, b][1] for b in range(n_blocks))  # every run stepped before the reduction
    assert [i for i, _ in done] == list(range(n_chunks))
    assert all(tick > finished(i) for i, tick in done)


def test_several_threads_overlap_a_chunks_reduction_with_the_next_chunks_steps():
    """With two buffers a block steps on while the chunk before is reduced: some step of chunk i + 1 starts before
    chunk i's last reduction ends (what the schedule is for; with one buffer none may)."""
    def overlaps(slots):
        events, _ = _record(6, 4, [3] * 6, 2, slots, seed=5)
        steps = {(i, b): s for kind, i, b, s, _ in events if kind == "step"}
        reduce_end = {}
        for kind, i, _, _, e in events:
            if kind == "reduce":
                reduce_end[i] = max(reduce_end.get(i, 0), e)
        return sum(steps[i + 1, b] < reduce_end[i] for i in range(5) for b in range(4))

    assert overlaps(2) > 0
    assert overlaps(1) == 0


@pytest.mark.parametrize("threads", [1, 2])
def test_a_failing_task_stops_the_schedule_and_is_raised(threads):
    ran = []

    def step(i, b):
        if (i, b) == (2, 1):
            raise RuntimeError("step failed")
        ran.append((i, b))

    with pytest.raises(RuntimeError, match="step failed"):
        run_chunks(50, 3, step, [1] * 50, lambda i, p: None, threads)
    assert len(ran) < 50 * 3  # stopped, not run to the end


def test_a_schedule_needs_a_buffer_and_every_chunks_parts():
    with pytest.raises(ValueError, match="slots"):
        run_chunks(2, 1, lambda i, b: None, [0, 0], lambda i, p: None, 1, slots=0)
    with pytest.raises(ValueError, match="parts"):
        run_chunks(2, 1, lambda i, b: None, [0], lambda i, p: None, 1)
