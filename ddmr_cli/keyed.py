"""A value carried into a memo (``functools.lru_cache``) that is hashed and compared by a key of its own."""

from __future__ import annotations

from typing import Any, Hashable

__all__ = ["Keyed"]


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
