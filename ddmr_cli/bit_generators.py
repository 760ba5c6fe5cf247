"""numpy's bit generators reached from compiled code by address, so one compiled call draws for many runs.

numba can take a ``numpy.random.Generator`` as an argument and draws numpy's own streams from it, but it unboxes
the generator at every call (its bit generator's ``ctypes`` interface, four ``ctypes.cast`` calls: 6.5-15 us
with the GIL held, against 0.6 us for a call here). A block of runs drawn one run per call paid that for every run
of every chunk, and two worker threads queued on the GIL for it. Here each generator's ``bitgen_t`` (numpy's C interface to a bit generator:
its state and its ``next_uint64``, ``next_uint32``, ``next_double`` functions, in that order; numpy's
``numpy/random/bitgen.h``, the documented C API for extending ``numpy.random``) is found once, from the
generator's ``capsule``, and compiled code builds numba's own bit-generator value from that address. numba's own
ziggurat (:func:`numba.np.random.distributions.random_standard_normal`, what ``Generator.standard_normal``
runs compiled) then draws the same numbers, and leaves the same state, as numpy's ``standard_normal``.

Both numba names used here (the bit generator's data model and the ziggurat) are numba's internals: where a
numba lacks them :data:`AVAILABLE` is False and numpy draws the noise, one generator per call (the same
numbers). The addresses are valid while their generators live: the caller keeps the generators.
"""

from __future__ import annotations

import ctypes
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


def addresses(generators: Sequence[np.random.Generator]) -> np.ndarray:
    """The address of each generator's ``bitgen_t`` (uint64), read from its bit generator's capsule (about 1 us
    each, with no ``ctypes`` interface built). Valid while the generators live."""
    pointer = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object, ctypes.c_char_p)(
        ("PyCapsule_GetPointer", ctypes.pythonapi))
    return np.array([pointer(g.bit_generator.capsule, b"BitGenerator") for g in generators], dtype=np.uint64)


def drawn_compiled() -> bool:
    """True when blocks of runs are drawn by one compiled call (numba installed and enabled, and its parts here)."""
    return AVAILABLE and jit_enabled()


__all__ = ["AVAILABLE", "addresses", "drawn_compiled", "standard_normals_of"]
