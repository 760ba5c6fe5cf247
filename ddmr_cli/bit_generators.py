"""numpy's bit generators for many runs at once: seeded together, and reached from compiled code by address, so one
compiled call draws for many runs.

**Seeding** (:func:`generators`). ``numpy.random.default_rng(seed)`` hashes the seed with ``SeedSequence`` in
Python (about 25 us a seed, the GIL held: 25 ms of a 1,000-run batch's set-up that no thread can share).
:func:`seed_words` runs the same hash (numpy's ``SeedSequence.mix_entropy`` and ``generate_state``, unsigned 32-bit
arithmetic) for every seed at once with numpy's array operations, and each ``PCG64`` is seeded from its words
through numpy's public ``ISeedSequence`` interface: the same state as ``default_rng(seed)`` (tested seed by seed,
and checked in each process before it is used) in about a fifth of the time.

**Drawing.**

numba can take a ``numpy.random.Generator`` as an argument and draws numpy's own streams from it, but it unboxes
the generator at every call (its bit generator's ``ctypes`` interface, four ``ctypes.cast`` calls: 6.5-15 us
with the GIL held, against 0.6 us for a call here). A block of runs drawn one run per call paid that for every run
of every chunk, and two worker threads queued on the GIL for it. Here each generator's ``bitgen_t`` (numpy's C
interface to a bit generator: its state and its ``next_uint64``, ``next_uint32``, ``next_double`` functions, in that
order; numpy's ``numpy/random/bitgen.h``, the documented C API for extending ``numpy.random``) is found once, from
the generator's ``capsule``, and compiled code builds numba's own bit-generator value from that address. numba's own
ziggurat (:func:`numba.np.random.distributions.random_standard_normal`, what ``Generator.standard_normal``
runs compiled) then draws the same numbers, and leaves the same state, as numpy's ``standard_normal``. The step
loop draws each run's normals one at a time as it steps (:func:`stream_of`, :func:`next_normal`: one definition,
compiled through these addresses, or as plain Python on the generators themselves); :func:`standard_normals_of`
draws a block of runs' rows at once (a run's first normals, the sensor's).

Both numba names used here (the bit generator's data model and the ziggurat) are numba's internals: where a
numba lacks them :data:`AVAILABLE` is False, and the compiled step loop cannot draw: :func:`require_compiled_draws`
says so before a run (``NUMBA_DISABLE_JIT=1`` runs the same numbers as Python). The addresses are valid while their generators live: the caller keeps the generators.
"""

from __future__ import annotations

import ctypes
import functools
from typing import Sequence

import numpy as np

from ddmr_cli.compiled import AVAILABLE as _NUMBA, cached_law, jit_enabled

#: fields of numpy's ``bitgen_t`` read here, in their order: the state, then the three draw functions
_BITGEN_FIELDS = ("state", "next_uint64", "next_uint32", "next_double")


def _numba_parts():
    """numba's modules this draw builds on, or None where numba is missing or lacks them."""
    if not _NUMBA:
        return None
    try:
        from numba.core import cgutils, types
        from numba.core.datamodel import default_manager
        from numba.core.extending import intrinsic
        from numba.np.random.distributions import random_standard_normal
        import numba.np.random.generator_core  # noqa: F401  (registers the bit generator's data model)
    except ImportError:
        return None
    fields = set(default_manager.lookup(types.NumPyRandomBitGeneratorType("bit_generator"))._fields)
    if not {"parent", "state_address", "state", "bit_generator"} | {f"fnptr_{f}" for f in _BITGEN_FIELDS[1:]} <= fields:
        return None
    return cgutils, types, intrinsic, random_standard_normal


_parts = _numba_parts()

#: True when :func:`standard_normals_of` is compiled (numba installed, with the parts it builds on)
AVAILABLE = _parts is not None

if AVAILABLE:  # defined at module level, not in a closure: numba caches a closure's code under a new key each process
    _cgutils, _types, _intrinsic, random_standard_normal = _parts

    @_intrinsic
    def bit_generator_at(typingctx, address):
        """numba's bit-generator value for the ``bitgen_t`` at ``address`` (a uint64)."""
        bitgen_type = _types.NumPyRandomBitGeneratorType("bit_generator")

        def codegen(context, builder, signature, args):
            word = context.get_value_type(_types.uintp)
            table = builder.inttoptr(args[0], word.as_pointer())
            loaded = [builder.load(builder.gep(table, [context.get_constant(_types.intp, i)]))
                      for i in range(len(_BITGEN_FIELDS))]
            bitgen = _cgutils.create_struct_proxy(bitgen_type)(context, builder)
            bitgen.parent = _cgutils.get_null_value(bitgen.parent.type)
            bitgen.state_address = bitgen.state = loaded[0]
            bitgen.fnptr_next_uint64, bitgen.fnptr_next_uint32, bitgen.fnptr_next_double = loaded[1:]
            bitgen.bit_generator = args[0]
            return bitgen._getvalue()

        return bitgen_type(_types.uint64), codegen

    @cached_law
    def standard_normals_of(addresses, out, first, end):
        """Fill ``out[r]`` (C-ordered, one row of normals after another) with the next standard normals of the bit
        generator at ``addresses[r]``, for runs ``first .. end - 1``: numpy's ``standard_normal(out=out[r])`` of
        each run's generator, the same numbers and the same state after them."""
        for r in range(first, end):
            bitgen = bit_generator_at(addresses[r])
            row = out[r]
            for i in range(row.shape[0]):
                for j in range(row.shape[1]):
                    row[i, j] = random_standard_normal(bitgen)
else:
    standard_normals_of = None


def stream_of(streams, r: int):
    """Run ``r``'s noise stream in the step loop: ``streams[r]``, its generator (``streams``: a list of
    ``numpy.random.Generator``) where the loop runs as Python; compiled, numba's bit-generator value of the
    ``bitgen_t`` at the address ``streams[r]`` (``streams``: :func:`addresses`)."""
    return streams[r]


def next_normal(stream) -> float:
    """The stream's next standard normal: numpy's ``Generator.standard_normal()``; compiled, numba's ziggurat on the
    same bit generator (what ``standard_normal`` runs compiled), the same number, the same state after it. A run's
    normals drawn one at a time in the loop are the numbers ``standard_normal(size)`` gives at once."""
    return stream.standard_normal()


if AVAILABLE:
    from numba.extending import overload

    @overload(stream_of, inline="always")
    def _stream_of_compiled(streams, r):
        def impl(streams, r):
            return bit_generator_at(streams[r])
        return impl

    @overload(next_normal, inline="always")
    def _next_normal_compiled(stream):
        def impl(stream):
            return random_standard_normal(stream)
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


def generators(seeds: Sequence[int], spawn_key: tuple[int, ...] = ()) -> list[np.random.Generator]:
    """``numpy.random.default_rng(SeedSequence(seed, spawn_key=spawn_key))`` of every seed: the same generators
    (the same state, the same streams), seeded from :func:`seed_words` where it applies."""
    words = seed_words(seeds, spawn_key) if _hash_agrees() else None
    if words is None:
        return [np.random.default_rng(np.random.SeedSequence(int(s), spawn_key=spawn_key)) for s in seeds]
    return [np.random.Generator(np.random.PCG64(_SeedWords(w))) for w in words]


def addresses(generators: Sequence[np.random.Generator]) -> np.ndarray:
    """The address of each generator's ``bitgen_t`` (uint64), read from its bit generator's capsule (about 1 us
    each, with no ``ctypes`` interface built). Valid while the generators live."""
    pointer = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object, ctypes.c_char_p)(
        ("PyCapsule_GetPointer", ctypes.pythonapi))
    return np.array([pointer(g.bit_generator.capsule, b"BitGenerator") for g in generators], dtype=np.uint64)


def require_compiled_draws() -> None:
    """Raise :class:`~ddmr_cli.errors.EngineUnavailable` where the step loop runs compiled but cannot draw compiled
    (a numba without the parts this module builds on): it draws its runs' normals as it steps, through them."""
    if jit_enabled() and not AVAILABLE:
        import numba

        from ddmr_cli.errors import EngineUnavailable

        raise EngineUnavailable(f"numba {numba.__version__} lacks the bit-generator parts ddmr's compiled step loop "
                                f"draws its noise through (ddmr_cli/bit_generators.py); install a numba that has them "
                                f"(0.68 has them) or set NUMBA_DISABLE_JIT=1 (the same numbers, slowly)")


def drawn_compiled() -> bool:
    """True when blocks of runs are drawn by one compiled call (numba installed and enabled, and its parts here)."""
    return AVAILABLE and jit_enabled()


__all__ = ["AVAILABLE", "addresses", "drawn_compiled", "generators", "next_normal", "require_compiled_draws",
           "seed_words", "standard_normals_of", "stream_of"]
