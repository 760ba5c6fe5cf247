"""Benchmark yardsticks (not part of the engine): :mod:`.reference`, the hand-fused kernel of the paper's loop that
``ddmr bench`` times beside the engine. Kept outside ``ddmr_cli/engine``, ``model``, ``control`` and
``compiled.py`` on purpose: the engine's compile-cache key hashes those, and this package must never invalidate
it."""
