"""Memos by key: a value carried into ``functools.lru_cache`` that is hashed and compared by a key of its own
(:class:`Keyed`), and a bounded store of what was computed, by what determines it (:class:`Kept`)."""

from __future__ import annotations

from typing import Any, Hashable

__all__ = ["Kept", "Keyed"]


class Keyed:
    """``value`` hashed and compared by ``key`` alone: a memo keyed by what determines its result (a config's
    digest, the types of a call's arguments) reaches the value it is computed from. A memoized function may drop
    ``value`` once it is done (``keyed.value = None``), so the memo keeps nothing large alive."""

    __slots__ = ("key", "value")

    def __init__(self, key: Hashable, value: Any) -> None:
        self.key, self.value = key, value

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Keyed) and other.key == self.key


class Kept:
    """What was computed, by a key of what determines it: at most ``size`` entries, the oldest dropped first.
    ``reused`` counts the values :meth:`get` handed back, each as ``weight`` (a run memo counts runs)."""

    def __init__(self, size: int, weight: int = 1) -> None:
        self.size, self.weight = size, weight
        self._kept: dict[Hashable, Any] = {}
        self.reused = 0

    def get(self, key: Hashable) -> Any | None:
        found = self._kept.get(key)
        if found is not None:
            self.reused += self.weight
        return found

    def put(self, key: Hashable, value: Any) -> None:
        if len(self._kept) >= self.size:
            del self._kept[next(iter(self._kept))]
        self._kept[key] = value
