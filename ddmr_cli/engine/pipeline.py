"""The threads' schedule of a batch's chunks: each block of runs steps on to its next chunk as soon as it has stepped
its own previous one, without waiting for the other blocks (docs/model.md §5, Threads).

A batch is stepped a chunk of steps at a time (the per-step buffers stay within a budget), and every chunk's seed
bands are reduced over all runs once every block of runs has stepped it. With a barrier after each phase (all
blocks stepped, then all reduced) the threads met twice a chunk, and a core slowed for a moment by the host held the
other one up each time. Here a chunk's tasks form a graph instead, and a thread takes whichever task is ready:

- ``step(i, b)``: block ``b`` through chunk ``i``; ready once block ``b`` has stepped chunk ``i - 1``, once chunk
  ``i - slots`` is reduced (chunk ``i`` writes its band rows into the buffer chunk ``i - slots`` used: ``slots``
  buffers take turns) and, for a chunk marked in ``after_all``, once every block has stepped chunk ``i - 1`` (the
  last chunk, shorter, reuses the other chunks' sensor-noise buffer);
- ``reduce(i, p)``: part ``p`` of chunk ``i``'s grid points over all runs; ready once every block has stepped it.

The oldest chunk's tasks go first. Every number is the same in any order: runs are independent, each grid point is
reduced over its own runs alone, and a block's chunks run in order. ``done(i)`` is called in the calling thread, in
order, as each chunk is stepped and reduced (progress). A task's exception stops the others and is raised here.
"""

from __future__ import annotations

import heapq
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Sequence

#: a task's kind, in the order of the ready heap within a chunk
STEP, REDUCE = 0, 1


class _Schedule:
    """What is stepped and reduced, and which tasks are ready (read and written under :attr:`lock` alone)."""

    def __init__(self, n_chunks: int, n_blocks: int, parts: list[int], slots: int, after_all: list[bool]) -> None:
        self.n_chunks, self.n_blocks, self.parts = n_chunks, n_blocks, parts
        self.slots, self.after_all = slots, after_all
        self.lock = threading.Condition()
        #: (chunk, kind, index) of the tasks ready to run, a heap: the oldest chunk first, its steps before its parts
        self.ready = [(0, STEP, b) for b in range(n_blocks)] if n_chunks else []
        #: (chunk, block): a block that stepped the chunk before, waiting for this one's buffers
        self.held: list[tuple[int, int]] = []
        self.stepped, self.reduced = [0] * n_chunks, [0] * n_chunks
        self.complete = [False] * n_chunks
        self.n_complete = 0
        self.running = 0  # tasks taken and not finished
        self.error: BaseException | None = None
        self.stopped = False

    def startable(self, chunk: int) -> bool:
        """May a block step ``chunk`` (its own chunk before it stepped)?"""
        if chunk >= self.slots and not self.complete[chunk - self.slots]:
            return False
        return not self.after_all[chunk] or self.stepped[chunk - 1] == self.n_blocks

    def finish(self, chunk: int, kind: int, index: int) -> None:
        """Account a finished task, make ready what it frees, wake the waiting threads."""
        if kind == STEP:
            self.stepped[chunk] += 1
            if chunk + 1 < self.n_chunks:
                self.held.append((chunk + 1, index))
            if self.stepped[chunk] == self.n_blocks:
                for part in range(self.parts[chunk]):
                    heapq.heappush(self.ready, (chunk, REDUCE, part))
                if self.parts[chunk] == 0:
                    self._completed(chunk)
        else:
            self.reduced[chunk] += 1
            if self.reduced[chunk] == self.parts[chunk]:
                self._completed(chunk)
        waiting = []
        for held in self.held:
            if self.startable(held[0]):
                heapq.heappush(self.ready, (held[0], STEP, held[1]))
            else:
                waiting.append(held)
        self.held = waiting
        self.running -= 1
        if self.n_complete == self.n_chunks:
            self.stop()
        elif not self.ready and not self.running:  # nothing could ever run again: a bug, said rather than hung
            self.fail(RuntimeError(f"the chunks' schedule stalled at chunk {self.complete.index(False)}"))
        self.lock.notify_all()

    def _completed(self, chunk: int) -> None:
        self.complete[chunk] = True
        self.n_complete += 1

    def fail(self, error: BaseException) -> None:
        self.error = self.error or error
        self.stop()

    def stop(self) -> None:
        self.stopped = True
        self.lock.notify_all()


def run_chunks(n_chunks: int, n_blocks: int, step: Callable[[int, int], None], parts: Sequence[int],
               reduce: Callable[[int, int], None], threads: int, slots: int = 2,
               after_all: Sequence[bool] | None = None, done: Callable[[int], None] | None = None) -> None:
    """Run ``step(i, b)`` for every chunk ``i < n_chunks`` and block ``b < n_blocks``, and ``reduce(i, p)`` for every
    part ``p < parts[i]``, in ``threads`` threads (1: in this thread), as the module describes.

    ``slots``: the band buffers that take turns (>= 1; with 1 a chunk's steps wait for the previous chunk's
    reduction); ``after_all[i]``: chunk ``i`` starts only once every block has stepped chunk ``i - 1``; ``done(i)``:
    called in this thread, in order of ``i``, once chunk ``i`` is stepped and reduced.
    """
    if slots < 1:
        raise ValueError(f"slots must be >= 1, not {slots}")
    if len(parts) != n_chunks:
        raise ValueError(f"parts must give every chunk's parts: {len(parts)} for {n_chunks} chunks")
    after_all = [False] * n_chunks if after_all is None else [bool(a) for a in after_all]
    if n_chunks == 0:
        return
    s = _Schedule(n_chunks, n_blocks, [int(p) for p in parts], slots, after_all)

    def take() -> tuple[int, int, int] | None:  # the next ready task, or None once stopped
        with s.lock:
            while not s.ready and not s.stopped:
                s.lock.wait()
            if s.stopped:
                return None
            s.running += 1
            return heapq.heappop(s.ready)

    def run(task: tuple[int, int, int]) -> bool:  # False: it failed (the schedule is stopped)
        chunk, kind, index = task
        try:
            (step if kind == STEP else reduce)(chunk, index)
        except BaseException as error:  # noqa: BLE001 - raised in the calling thread
            with s.lock:
                s.fail(error)
            return False
        with s.lock:
            s.finish(chunk, kind, index)
        return True

    def work() -> None:
        while (task := take()) is not None and run(task):
            pass

    reported = 0
    if threads <= 1:  # in this thread: the heap's order, each chunk reported as it completes
        while (task := take()) is not None and run(task):
            while reported < n_chunks and s.complete[reported]:
                if done is not None:
                    done(reported)
                reported += 1
        if s.error is not None:
            raise s.error
        return
    with ThreadPoolExecutor(threads) as pool:
        workers = [pool.submit(work) for _ in range(threads)]
        try:
            while reported < n_chunks:
                with s.lock:
                    while not s.complete[reported] and s.error is None:
                        s.lock.wait()
                    if s.error is not None:
                        break
                if done is not None:
                    done(reported)
                reported += 1
        finally:
            with s.lock:
                s.stop()
        for worker in workers:
            worker.result()
    if s.error is not None:
        raise s.error


__all__ = ["run_chunks"]
