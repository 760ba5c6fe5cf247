"""numpy's ``default_rng`` streams for many runs at once: each run's ``PCG64`` held as four words of one array,
seeded for every run at once and stepped by compiled code, so one compiled call draws for many runs and the step
loop draws its runs' normals as it steps.

**Seeding** (:func:`states`). ``numpy.random.default_rng(seed)`` hashes the seed with ``SeedSequence`` in Python
(about 25 us a seed, the GIL held) and builds a ``Generator`` object around a ``PCG64`` (2 us more a run, and a few
hundred bytes). :func:`seed_words` runs the same hash (numpy's ``SeedSequence.mix_entropy`` and ``generate_state``,
unsigned 32-bit arithmetic) for every seed at once with numpy's array operations, and a compiled loop seeds each
run's ``PCG64`` from its words as numpy's ``pcg64_set_seed`` does, with no ``Generator`` object: 1,000 runs seeded
(and their first normals drawn) in 0.3 ms where the objects took 2.3 ms, all of it serial before the threads start;
at 10,000 runs 0.3 MB held where the objects held 7.9 MB.

**The generator** (numpy's ``numpy/random/src/pcg64``: ``PCG64``, the bit generator of ``default_rng``). Its state
is a 128-bit LCG, ``state <- state * M + inc`` (``M`` numpy's ``PCG_DEFAULT_MULTIPLIER_128``, ``inc`` odd); each
64-bit output is the XSL-RR of the new state: its high and low halves xor-ed, rotated right by its top 6 bits. A
run's state is a row ``(state_hi, state_lo, inc_hi, inc_lo)`` of a ``uint64`` array (:func:`states`); compiled code
steps it with LLVM's own 128-bit integers (:func:`_lcg_step`, one multiply-add), the words passed by value, so that
a run's draws keep them in registers (a row stored and read back at every draw made a block's draws 45 % slower).

**Drawing.** :func:`next_normal` is numpy's ``Generator.standard_normal()``: as plain Python, the generator's own
method; compiled, numpy's ziggurat (``random_standard_normal``, the transcription numba ships for its ``Generator``
support, with its tables) on the run's words (:func:`stream_of` reads them from its row, :func:`keep` writes them
back). The same number, and the generator's state after it is numpy's (tested over 50,000 normals one at a time and
600,000 by block, the ziggurat's tail and wedge included). The step loop draws each run's normals one at a time as it
steps (:func:`next_normal`); :func:`standard_normals_of` draws a block of runs' rows at once (a run's first normals,
the sensor's). :func:`generator_at` gives back a numpy
``Generator`` at a row's state, to go on drawing from it in numpy.

The ziggurat's tables are numba's (``numba.np.random._constants``, numpy's ``ziggurat_constants.h``): where a numba
lacks them :data:`AVAILABLE` is False, and the compiled step loop cannot draw: :func:`require_compiled_draws` says
so before a run (``NUMBA_DISABLE_JIT=1`` runs the same numbers as Python, on numpy's generators).
"""

from __future__ import annotations

import functools
from typing import Sequence

import numpy as np

from ddmr_cli.compiled import AVAILABLE as _NUMBA, cached_law, jit_enabled

#: numpy's ``PCG_DEFAULT_MULTIPLIER_128`` (``numpy/random/src/pcg64/pcg64.h``), the LCG's multiplier
MULTIPLIER = 0x2360ED051FC65DA44385DF649FCCF645
#: a run's row of :func:`states`: the 128-bit state and increment, high word first
STATE_WORDS = ("state_hi", "state_lo", "inc_hi", "inc_lo")


def _numba_parts():
    """numba's parts this draw builds on (``intrinsic`` and the ziggurat's tables), or None where numba is missing
    or lacks them."""
    if not _NUMBA:
        return None
    try:
        from llvmlite import ir
        from numba.core import types
        from numba.core.extending import intrinsic
        from numba.np.random._constants import fi_double, ki_double, wi_double, ziggurat_nor_inv_r, ziggurat_nor_r
    except ImportError:
        return None
    return ir, types, intrinsic, (wi_double, ki_double, fi_double, ziggurat_nor_r, ziggurat_nor_inv_r)


_parts = _numba_parts()

#: True when the draws are compiled (numba installed, with the parts they build on)
AVAILABLE = _parts is not None

if AVAILABLE:  # defined at module level, not in a closure: numba caches a closure's code under a new key each process
    _ir, _types, _intrinsic, _tables = _parts
    _WI, _KI, _FI, _ZIGGURAT_R, _ZIGGURAT_INV_R = _tables
    _SIGN = np.array([1.0, -1.0])  # x * -1.0 is -x, to the bit (a sign bit of 1 negates)
    from numba import njit as _njit, uint64 as _u64
    from numba.extending import overload

    @_intrinsic
    def _lcg_step(typingctx, state_hi, state_lo, inc_hi, inc_lo):
        """PCG64's LCG step in 128-bit integers: ``(state * MULTIPLIER + inc)`` as its (high, low) words."""
        words = _types.UniTuple(_types.uint64, 2)

        def codegen(context, builder, signature, args):
            i128, i64 = _ir.IntType(128), _ir.IntType(64)

            def joined(high, low):
                return builder.or_(builder.shl(builder.zext(high, i128), _ir.Constant(i128, 64)),
                                   builder.zext(low, i128))

            new = builder.add(builder.mul(joined(args[0], args[1]), _ir.Constant(i128, MULTIPLIER)),
                              joined(args[2], args[3]))
            high = builder.trunc(builder.lshr(new, _ir.Constant(i128, 64)), i64)
            return context.make_tuple(builder, words, (high, builder.trunc(new, i64)))

        return words(_types.uint64, _types.uint64, _types.uint64, _types.uint64), codegen

    def _next_output(high, low, inc_hi, inc_lo):
        """PCG64's next output (numpy's ``pcg64_next64``) from the state ``(high, low)`` and increment: the LCG
        stepped, then XSL-RR of the new state; returns ``(output, high, low)``, the new state. The state goes by
        value, so a block of draws keeps it in registers."""
        high, low = _lcg_step(high, low, inc_hi, inc_lo)
        rotation = high >> _u64(58)
        folded = high ^ low
        return (folded >> rotation) | (folded << ((_u64(64) - rotation) & _u64(63))), high, low

    def _next_double(high, low, inc_hi, inc_lo):
        """numpy's ``pcg64_next_double``: the top 53 bits of the next output, in [0, 1); and the new state."""
        bits, high, low = _next_output(high, low, inc_hi, inc_lo)
        return (bits >> _u64(11)) * (1.0 / 9007199254740992.0), high, low

    def _ziggurat_try(high, low, inc_hi, inc_lo):
        """One try of numpy's ziggurat on the next output: its low 8 bits pick the layer ``idx``, the next the sign,
        the 52 above it the abscissa ``rabs``; ``x`` the point in the layer's rectangle, signed; and the new state."""
        bits, high, low = _next_output(high, low, inc_hi, inc_lo)
        idx = bits & 0xff
        bits >>= 8
        rabs = (bits >> 1) & 0x000fffffffffffff
        return idx, rabs, rabs * _WI[idx] * _SIGN[bits & 0x1], high, low

    def _normal(high, low, inc_hi, inc_lo):
        """numpy's ``random_standard_normal`` (``distributions.c``, its ziggurat) on the generator ``(high, low,
        inc_hi, inc_lo)``, as numba transcribes it for its ``Generator`` support: ``(x, high, low)``, the normal and
        the new state. The first try, which returns about 99 % of the time, here; the rest in
        :func:`_ziggurat_rest`."""
        idx, rabs, x, high, low = _ziggurat_try(high, low, inc_hi, inc_lo)
        if rabs >= _KI[idx]:
            x, high, low = _ziggurat_rest(high, low, inc_hi, inc_lo, idx, rabs, x)
        return x, high, low

    def _ziggurat_rest(high, low, inc_hi, inc_lo, idx, rabs, x):
        """The ziggurat past a try that fell outside its layer's rectangle: the tail (``idx == 0``) or the wedge's
        test, then the next try, line for line as numba has them; ``(x, high, low)``."""
        while 1:
            if idx == 0:
                while 1:
                    u, high, low = _next_double(high, low, inc_hi, inc_lo)
                    xx = -_ZIGGURAT_INV_R * np.log1p(-u)
                    u, high, low = _next_double(high, low, inc_hi, inc_lo)
                    yy = -np.log1p(-u)
                    if yy + yy > xx * xx:
                        if (rabs >> 8) & 0x1:
                            return -(_ZIGGURAT_R + xx), high, low
                        return _ZIGGURAT_R + xx, high, low
            else:
                u, high, low = _next_double(high, low, inc_hi, inc_lo)
                if (_FI[idx - 1] - _FI[idx]) * u + _FI[idx] < np.exp(-0.5 * x * x):
                    return x, high, low
            idx, rabs, x, high, low = _ziggurat_try(high, low, inc_hi, inc_lo)
            if rabs < _KI[idx]:
                return x, high, low

    # inlined into numba's IR: the words' steps and the ziggurat's first try; the rest (a loop with returns inside,
    # rare) is called, as numba's whole ziggurat is. Each is inlined at one call site per function: numba's inliner,
    # given a function with a branch inlined twice into another, warns of variables out of scope
    # (NumbaIRAssumptionWarning)
    _next_output = _njit(inline="always")(_next_output)
    _next_double = _njit(inline="always")(_next_double)
    _ziggurat_try = _njit(inline="always")(_ziggurat_try)
    _ziggurat_rest = _njit(_ziggurat_rest)
    _normal = _njit(inline="always")(_normal)

    @cached_law
    def standard_normals_of(states, out, first, end):
        """Fill ``out[r]`` (C-ordered, one row of normals after another) with the next standard normals of run
        ``r``'s generator (``states[r]``, :func:`states`), for runs ``first .. end - 1``: numpy's
        ``standard_normal(out=out[r])`` of each run's generator, the same numbers and the same state after them."""
        for r in range(first, end):
            high, low, inc_hi, inc_lo = states[r, 0], states[r, 1], states[r, 2], states[r, 3]
            for i in range(out.shape[1]):  # the state in registers, written back once
                for j in range(out.shape[2]):
                    x, high, low = _normal(high, low, inc_hi, inc_lo)
                    out[r, i, j] = x
            states[r, 0], states[r, 1] = high, low

    @cached_law
    def _seeded(words, out):
        """numpy's ``pcg64_set_seed`` of each run's four seed words (``SeedSequence.generate_state(4, uint64)``:
        the state's, then the increment's) into ``out[r]``: ``inc = 2 w + 1``, the state stepped from 0, the seed
        added, stepped again."""
        for r in range(words.shape[0]):
            inc_hi = (words[r, 2] << _u64(1)) | (words[r, 3] >> _u64(63))
            inc_lo = (words[r, 3] << _u64(1)) | _u64(1)
            high, low = _lcg_step(_u64(0), _u64(0), inc_hi, inc_lo)
            added = low + words[r, 1]
            high = high + words[r, 0] + (_u64(1) if added < low else _u64(0))
            high, low = _lcg_step(high, added, inc_hi, inc_lo)
            out[r, 0], out[r, 1], out[r, 2], out[r, 3] = high, low, inc_hi, inc_lo
else:
    standard_normals_of = None


def stream_of(streams, r: int):
    """Run ``r``'s stream, for :func:`next_normal`: its ``numpy.random.Generator`` (``streams``: a list of them) as
    plain Python; compiled, its row of :func:`states` read into four words (the step loop keeps them in registers;
    :func:`keep` writes them back)."""
    return streams[r]


def next_normal(stream):
    """``(x, stream)``: the stream's next standard normal and the stream after it. As plain Python, numpy's
    ``Generator.standard_normal()`` (the generator itself changes); compiled, numpy's ziggurat on the words
    (module docstring): the same number, the same state after it. A run's normals drawn one at a time in the loop
    are the numbers ``standard_normal(size)`` gives at once."""
    return stream.standard_normal(), stream


def keep(streams, r: int, stream) -> None:
    """Write run ``r``'s stream back after its draws (compiled: the words into its row of :func:`states`; a numpy
    generator holds its own state)."""


if AVAILABLE:
    @overload(stream_of, inline="always")
    def _stream_of_compiled(streams, r):
        def impl(streams, r):
            return streams[r, 0], streams[r, 1], streams[r, 2], streams[r, 3]
        return impl

    @overload(next_normal, inline="always")
    def _next_normal_compiled(stream):
        def impl(stream):
            x, high, low = _normal(stream[0], stream[1], stream[2], stream[3])
            return x, (high, low, stream[2], stream[3])
        return impl

    @overload(keep, inline="always")
    def _keep_compiled(streams, r, stream):
        def impl(streams, r, stream):
            streams[r, 0], streams[r, 1] = stream[0], stream[1]
        return impl


#: numpy's ``SeedSequence`` constants (``numpy/random/bit_generator.pyx``): the pool's hash, the mixer, the output hash
_INIT_A, _MULT_A, _MIX_MULT_L, _MIX_MULT_R = 0x43B0D7E5, 0x931E8875, 0xCA01F9DD, 0x4973F715
_INIT_B, _MULT_B = 0x8B51F9DD, 0x58F38DED
_POOL_SIZE, _XSHIFT = 4, 16


def seed_words(seeds: Sequence[int], spawn_key: tuple[int, ...] = ()) -> np.ndarray | None:
    """``SeedSequence(seed, spawn_key=spawn_key).generate_state(4, numpy.uint64)`` of every seed, shape ``(n, 4)``:
    the words ``PCG64`` seeds itself from. Seeds and keys of one 32-bit word each (0 <= value < 2**32); None for
    any other (then each seed goes through ``SeedSequence`` itself)."""
    values = [int(s) for s in seeds] + [int(k) for k in spawn_key]
    if any(v < 0 or v >= 2**32 for v in values):
        return None
    n = len(seeds)
    u32 = np.uint32
    entropy = [np.array(values[:n], dtype=u32)]  # the seed's one word (0 is the word 0)
    if spawn_key:  # a spawned sequence pads its own entropy to the pool's size, then appends the key's words
        entropy += [np.zeros(n, u32)] * (_POOL_SIZE - 1) + [np.full(n, k, u32) for k in spawn_key]
    hash_const = u32(_INIT_A)

    def hashmix(value):
        nonlocal hash_const
        value = value ^ hash_const
        hash_const = u32(hash_const * u32(_MULT_A))
        value = value * hash_const
        return value ^ (value >> u32(_XSHIFT))

    def mix(x, y):
        result = u32(_MIX_MULT_L) * x - u32(_MIX_MULT_R) * y
        return result ^ (result >> u32(_XSHIFT))

    with np.errstate(over="ignore"):  # unsigned 32-bit arithmetic wraps, as in numpy's C
        pool = [hashmix(entropy[i] if i < len(entropy) else np.zeros(n, u32)) for i in range(_POOL_SIZE)]
        for src in range(_POOL_SIZE):
            for dst in range(_POOL_SIZE):
                if src != dst:
                    pool[dst] = mix(pool[dst], hashmix(pool[src]))
        for src in range(_POOL_SIZE, len(entropy)):
            for dst in range(_POOL_SIZE):
                pool[dst] = mix(pool[dst], hashmix(entropy[src]))
        words = np.empty((n, 2 * _POOL_SIZE), u32)  # generate_state(4, uint64): 8 words of 32 bits
        hash_const = u32(_INIT_B)
        for i in range(2 * _POOL_SIZE):
            value = pool[i % _POOL_SIZE] ^ hash_const
            hash_const = u32(hash_const * u32(_MULT_B))
            value = value * hash_const
            words[:, i] = value ^ (value >> u32(_XSHIFT))
    return words.astype("<u4").view("<u8").astype(np.uint64)


class _SeedWords(np.random.bit_generator.ISeedSequence):
    """A seed sequence that hands ``PCG64`` words already hashed (numpy's ``ISeedSequence`` interface)."""

    __slots__ = ("words",)

    def __init__(self, words: np.ndarray) -> None:
        self.words = words

    def generate_state(self, n_words: int, dtype=np.uint32) -> np.ndarray:
        if n_words != _POOL_SIZE or np.dtype(dtype) != np.uint64:
            raise ValueError(f"only PCG64's request (4 uint64 words) is kept, not {n_words} of {np.dtype(dtype)}")
        return self.words


@functools.lru_cache(maxsize=1)
def _hash_agrees() -> bool:
    """True when :func:`seed_words` gives this numpy's ``SeedSequence`` words (checked once per process, on seeds
    that reach every branch: 0, 1, the largest one-word seed, with and without a spawn key)."""
    seeds = [0, 1, 12345, 2**32 - 1]
    return all(np.array_equal(seed_words(seeds, key)[i],
                              np.random.SeedSequence(s, spawn_key=key).generate_state(_POOL_SIZE, np.uint64))
               for key in ((), (1,), (3, 7)) for i, s in enumerate(seeds))


def _words(seeds: Sequence[int], spawn_key: tuple[int, ...]) -> np.ndarray:
    """``SeedSequence(seed, spawn_key=spawn_key).generate_state(4, uint64)`` of every seed, shape ``(n, 4)``: by
    :func:`seed_words` where it applies, else by numpy's ``SeedSequence`` seed by seed."""
    words = seed_words(seeds, spawn_key) if _hash_agrees() else None
    if words is None:
        words = np.array([np.random.SeedSequence(int(s), spawn_key=spawn_key).generate_state(_POOL_SIZE, np.uint64)
                          for s in seeds], dtype=np.uint64).reshape(len(seeds), _POOL_SIZE)
    return words


def generators(seeds: Sequence[int], spawn_key: tuple[int, ...] = ()) -> list[np.random.Generator]:
    """``numpy.random.default_rng(SeedSequence(seed, spawn_key=spawn_key))`` of every seed: the same generators
    (the same state, the same streams), seeded from :func:`seed_words` where it applies."""
    return [np.random.Generator(np.random.PCG64(_SeedWords(w))) for w in _words(seeds, spawn_key)]


def states(seeds: Sequence[int], spawn_key: tuple[int, ...] = ()) -> np.ndarray:
    """The ``PCG64`` of ``default_rng(SeedSequence(seed, spawn_key=spawn_key))`` of every seed, as rows
    ``(state_hi, state_lo, inc_hi, inc_lo)`` of a ``uint64`` array (:data:`STATE_WORDS`): the generators
    :func:`generators` gives, seeded at once by one compiled call, without their objects (:data:`AVAILABLE` must
    hold)."""
    out = np.empty((len(seeds), len(STATE_WORDS)), dtype=np.uint64)
    _seeded(np.ascontiguousarray(_words(seeds, spawn_key), dtype=np.uint64), out)
    return out


def state_of(row: np.ndarray) -> dict:
    """A row of :func:`states` as numpy's ``PCG64.state`` spells it (``bit_generator.state``)."""
    high, low, inc_high, inc_low = (int(v) for v in row)
    return {"bit_generator": "PCG64", "state": {"state": (high << 64) | low, "inc": (inc_high << 64) | inc_low},
            "has_uint32": 0, "uinteger": 0}


def generator_at(row: np.ndarray) -> np.random.Generator:
    """A numpy ``Generator`` at a row's state (:func:`state_of`): it draws on where the row's draws stopped."""
    bit_generator = np.random.PCG64()
    bit_generator.state = state_of(row)
    return np.random.Generator(bit_generator)


def require_compiled_draws() -> None:
    """Raise :class:`~ddmr_cli.errors.EngineUnavailable` where the step loop runs compiled but cannot draw compiled
    (a numba without the parts this module builds on): it draws its runs' normals as it steps, with them."""
    if jit_enabled() and not AVAILABLE:
        import numba

        from ddmr_cli.errors import EngineUnavailable

        raise EngineUnavailable(f"numba {numba.__version__} lacks the parts ddmr's compiled step loop draws its noise "
                                f"with (ddmr_cli/bit_generators.py: numba's ziggurat tables); install a numba that has "
                                f"them (0.68 has them) or set NUMBA_DISABLE_JIT=1 (the same numbers, slowly)")


def drawn_compiled() -> bool:
    """True when blocks of runs are drawn by one compiled call (numba installed and enabled, and its parts here)."""
    return AVAILABLE and jit_enabled()


__all__ = ["AVAILABLE", "MULTIPLIER", "STATE_WORDS", "drawn_compiled", "generator_at", "generators", "keep",
           "next_normal", "require_compiled_draws", "seed_words", "standard_normals_of", "state_of", "states",
           "stream_of"]
