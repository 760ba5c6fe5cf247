"""Elementary functions the laws share: ``exp`` of a non-positive argument and ``(sin, cos)``, written out as
arithmetic (fdlibm's algorithms: e_exp.c; k_sin.c, k_cos.c and e_rem_pio2.c's medium case with both iterations).

Why not libm's. A law that calls libm's ``exp`` in a loop (the RBF network's basis (27), one exp a neuron) makes
the compiler call it once per element, out of line: numba has no vector exp without Intel's SVML. Written as
arithmetic, branch-free, the same loop is vectorised by LLVM (AVX-512: 8 neurons an instruction), and the
exponents below :data:`EXP_ZERO`, where libm takes its slow underflow path, cost what the others cost.
Measured on the network's laws alone (10 neurons, 7 of them live at the paper's 33 rad/s, one core):
110 -> 78 ns a control step. And the numbers are the same on every CPU: these are IEEE-754 additions and
multiplications in a fixed order (no fused multiply-add: the laws are compiled without fast-math flags), where
glibc's ``exp`` and ``sin`` pick an implementation by the CPU's features at load time.

Accuracy: at most 1 ulp from the correctly rounded value (glibc's are within about 0.5 ulp), so a run's numbers
differ from libm's by rounding (tests/test_elementary.py holds both to 1 ulp of numpy's on about 27,000 arguments each).
Compiled and as plain Python (the fallback without numba) they give the same bits.
"""

from __future__ import annotations

import math

from ddmr_cli.compiled import AVAILABLE, law

#: below this exponent ``exp`` is exactly 0.0 (``exp(-745.14)`` is half the smallest subnormal, 2^-1075)
EXP_ZERO = -746.0

# fdlibm's constants (e_exp.c, k_sin.c, k_cos.c, e_rem_pio2.c)
_P1, _P2, _P3 = 1.66666666666666019037e-01, -2.77777777770155933842e-03, 6.61375632143793436117e-05
_P4, _P5 = -1.65339022054652515390e-06, 4.13813679705723846039e-08
_LN2_HI, _LN2_LO, _INV_LN2 = 6.93147180369123816490e-01, 1.90821492927058770002e-10, 1.44269504088896338700e+00
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11
_INV_PIO2 = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e+00
_PIO2_2, _PIO2_2T = 6.07710050630396597660e-11, 2.02226624879595063154e-21


def pow2(k):
    """``2.0 ** k`` for an integer ``-1022 <= k <= 1023``; compiled, the exponent's bits (no call)."""
    return math.ldexp(1.0, int(k))


if AVAILABLE:
    from llvmlite import ir
    from numba import types
    from numba.extending import intrinsic, overload

    @intrinsic
    def _bits_to_float(typingctx, bits):
        """The float64 whose bits are the int64 ``bits``."""
        if bits != types.int64:
            return None

        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], ir.DoubleType())

        return types.float64(types.int64), codegen

    @overload(pow2, inline="always")
    def _pow2_compiled(k):
        def impl(k):
            return _bits_to_float((int(k) + 1023) << 52)

        return impl


@law
def exp_neg(x):
    """``exp(x)`` for ``x <= 0`` (fdlibm's e_exp.c), branch-free: exactly 0 below :data:`EXP_ZERO` (computed on 0
    there, not on an underflow); NaN for NaN and outside the domain (``x > 0``)."""
    inside = EXP_ZERO <= x <= 0.0  # False for NaN
    xs = x if inside else 0.0
    kf = math.floor(xs * _INV_LN2 + 0.5)
    hi = xs - kf * _LN2_HI
    lo = kf * _LN2_LO
    r = hi - lo
    t = r * r
    c = r - t * (_P1 + t * (_P2 + t * (_P3 + t * (_P4 + t * _P5))))
    y = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    k = int(kf)
    half = k >> 1
    out = y * pow2(half) * pow2(k - half)  # two factors: 2^k may be subnormal
    return out if inside else (0.0 if x < EXP_ZERO else math.nan)


@law
def sincos(x):
    """``(sin x, cos x)`` for ``|x| < 2^19 pi / 2``, branch-free (fdlibm's kernels on ``x`` reduced by the nearest
    multiple of pi/2 to 118 bits)."""
    fn = math.floor(x * _INV_PIO2 + 0.5)
    t = x - fn * _PIO2_1
    w2 = fn * _PIO2_2
    r = t - w2
    w = fn * _PIO2_2T - ((t - r) - w2)
    a = r - w
    b = (r - a) - w
    z = a * a
    v = z * a
    rs = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    ks = a - ((z * (0.5 * b - v * rs) - b) - v * _S1)
    zz = z * z
    rc = z * (_C1 + z * (_C2 + z * _C3)) + zz * zz * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    one_hz = 1.0 - hz
    kc = one_hz + (((1.0 - one_hz) - hz) + (z * rc - a * b))
    q = int(fn)
    odd = (q & 1) != 0
    s = (kc if odd else ks) * (1.0 - (q & 2))
    c = (ks if odd else kc) * (1.0 - ((q + 1) & 2))
    return s, c


__all__ = ["EXP_ZERO", "exp_neg", "pow2", "sincos"]
