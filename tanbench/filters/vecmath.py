"""Logarithm and exponential written for loops that LLVM vectorises.

``math.log`` and ``math.exp`` are calls into the C library: a loop over particles that
calls them runs one element at a time, and each call costs as much as the rest of the
likelihood. These versions are straight-line arithmetic on the bits of the double (no
branch, no call, no table), so a loop over particles that uses them compiles to SIMD
instructions (4 doubles at a time with AVX2). Both follow the classic fdlibm algorithms
(Sun Microsystems' freely distributable libm, the basis of most C libraries): argument
reduction by powers of two, then a minimax polynomial on a small interval. They are
accurate to about 1 ulp over the ranges the filters use; the tests compare them with
numpy's ``log`` and ``exp`` (their plain-numpy references) over those ranges.

* :func:`log_positive` (x): x > 0 and normal (not subnormal); +inf and NaN are returned as
  they are;
* :func:`exp_nonpositive` (x): x <= 0 (the weights' exp(log w - max)), -inf gives 0; below
  -708 (where exp leaves the normal range) it returns 0.

Integer/float reinterpretations are :func:`float_bits` and :func:`bits_float` (LLVM
bitcasts, free in a vector loop).

The ``lane_*`` intrinsics (below) run the filters' fixed-order sums over particles, four
interleaved chains, as the four lanes of one vector: the same bits as the scalar chains, which
LLVM leaves scalar.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from tanbench.filters import FASTMATH


@intrinsic
def float_bits(typingctx, x):
    """The 64 bits of a float64 as an int64 (a bitcast, no conversion)."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return types.int64(types.float64), codegen


@intrinsic
def bits_float(typingctx, i):
    """The float64 whose 64 bits are the int64 ``i`` (a bitcast, no conversion)."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(types.int64), codegen


EXP_52 = np.int64(0x4330000000000000)  # the bits of 2^52: OR-ed with k < 2^52 they are 2^52 + k
TWO_52 = 4503599627370496.0
LOW_32 = np.int64(0xFFFFFFFF)


@nb.njit(cache=True, inline="always")
def exact_float_53(v):
    """The float64 of an integer ``v`` in [0, 2^53) (exact), as ``np.float64(v)`` gives it, from
    two 2^52-offset bit patterns: AVX2 has no int64 -> float64 conversion, and LLVM turns one in
    a SIMD loop into four scalar conversions."""
    high = bits_float((v >> 32) | EXP_52) - TWO_52
    low = bits_float((v & LOW_32) | EXP_52) - TWO_52
    return high * 4294967296.0 + low


# log: x = 2^k m, m in [sqrt(2)/2, sqrt(2)); log m = f - f^2/2 + s (f^2/2 + R(s^2)), f = m - 1,
# s = f / (2 + f); R is fdlibm's minimax polynomial (e_log.c, Lg1..Lg7)
LN2_HI = 6.93147180369123816490e-01
LN2_LO = 1.90821492927058770002e-10
LG1, LG2, LG3, LG4 = 6.666666666666735130e-01, 3.999999999940941908e-01, 2.857142874366239149e-01, \
    2.222219843214978396e-01
LG5, LG6, LG7 = 1.818357216161805012e-01, 1.531383769920937332e-01, 1.479819860511658591e-01
SQRT2 = 1.4142135623730951
MANTISSA = 0x000FFFFFFFFFFFFF
ONE_BITS = 0x3FF0000000000000


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def log_positive(x):
    """Natural logarithm of a positive, finite, normal float64 (+inf gives +inf); branch free."""
    i = float_bits(x)
    k = np.int32((i >> 52) & 0x7FF) - np.int32(1023)
    m = bits_float((i & MANTISSA) | ONE_BITS)  # in [1, 2)
    high = m > SQRT2
    m = m * 0.5 if high else m
    kf = np.float64(k) + (1.0 if high else 0.0)
    f = m - 1.0
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    r = z * (LG1 + w * (LG3 + w * (LG5 + w * LG7))) + w * (LG2 + w * (LG4 + w * LG6))
    half_f2 = 0.5 * f * f
    out = kf * LN2_HI - ((half_f2 - (s * (half_f2 + r) + kf * LN2_LO)) - f)
    return out if x < np.inf else x  # +inf and NaN as they are


# exp: x = k ln2 + r, |r| <= ln2/2; exp(r) = 1 + 2r / (2 - c) with c = r - r^2 (P1 + ...) (fdlibm e_exp.c)
INV_LN2 = 1.44269504088896338700e+00
P1, P2, P3 = 1.66666666666666019037e-01, -2.77777777770155933842e-03, 6.61375632143793436117e-05
P4, P5 = -1.65339022054652515390e-06, 4.13813679705723846039e-08
ROUND = 6755399441055744.0  # 1.5 * 2^52: adding and subtracting it rounds to the nearest integer
EXP_MIN = -708.0  # below this exp(x) is not a normal double: 0 is returned


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def exp_nonpositive(x):
    """exp(x) for x <= 0 (-inf gives 0, x < -708 gives 0, NaN gives NaN); branch free."""
    low = x < EXP_MIN
    xx = EXP_MIN if low else x
    kf = (xx * INV_LN2 + ROUND) - ROUND
    hi = xx - kf * LN2_HI
    lo = kf * LN2_LO
    r = hi - lo
    t = r * r
    c = r - t * (P1 + t * (P2 + t * (P3 + t * (P4 + t * P5))))
    y = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    scale = bits_float(np.int64(np.int32(kf) + np.int32(1023)) << 52)
    out = y * scale
    return 0.0 if low else out


# ---- sums in four fixed chains, as the lanes of one vector ------------------------------------
# The filters' sums over particles run in four interleaved chains added in a fixed order at the end
# (the same bits on every machine; ``filters/estimate.py``, ``filters/resample.py``). Written as four
# scalar chains, LLVM keeps them scalar; these intrinsics run chain l in lane l of one 4-double vector,
# element j = l (mod 4) after element j - 4: the same operations in the same order, so the same bits,
# four elements an instruction. Each takes C-contiguous float64 arrays and ``quads`` (their first
# 4 ``quads`` elements), and returns the four lanes of each sum; the callers add the last elements
# to lane 0 and the lanes as (l0 + l1) + (l2 + l3), as the scalar chains do.
V4 = ir.VectorType(ir.DoubleType(), 4)
INV_TWO_PI = 1.0 / (2.0 * math.pi)  # the scalar wrap's (a + pi) / (2 pi), multiplied as "arcp" compiles it


def _contiguous_f8(*arrays) -> bool:
    return all(isinstance(a, types.Array) and a.ndim == 1 and a.layout == "C" and a.dtype == types.float64
               for a in arrays)


def _splat(value):
    return ir.Constant(V4, [value] * 4)


def _broadcast(builder, value, vector_type=V4):
    out = ir.Constant(vector_type, ir.Undefined)
    for lane in range(4):
        out = builder.insert_element(out, value, ir.Constant(ir.IntType(32), lane))
    return out


def _lanes(builder, vector):
    return [builder.extract_element(vector, ir.Constant(ir.IntType(32), lane)) for lane in range(4)]


def _load_quad(builder, array, first):
    """The four doubles of ``array`` (a ``make_array`` proxy) from element ``first`` on, as one vector."""
    return builder.load(builder.bitcast(builder.gep(array.data, [first]), V4.as_pointer()), align=8)


def _lane_loop(context, builder, signature, args, narrays, sums, step):
    """Codegen of a lane sum: ``narrays`` array arguments, then the other arguments (scalars, last
    ``quads``); ``step(builder, loaded vectors, scalar args)`` gives the ``sums`` vectors to add at
    every quad. Returns the lanes of every sum as a tuple."""
    arrays = [context.make_array(t)(context, builder, v) for t, v in zip(signature.args[:narrays], args[:narrays])]
    accs = [cgutils.alloca_once_value(builder, _splat(0.0)) for _ in range(sums)]
    scalars = [_broadcast(builder, v) for v in args[narrays:-1]]
    with cgutils.for_range(builder, args[-1]) as loop:
        first = builder.mul(loop.index, ir.Constant(loop.index.type, 4))
        vectors = [_load_quad(builder, a, first) for a in arrays]
        for acc, term in zip(accs, step(builder, vectors, scalars)):
            builder.store(builder.fadd(builder.load(acc), term), acc)
    lanes = [v for acc in accs for v in _lanes(builder, builder.load(acc))]
    return context.make_tuple(builder, signature.return_type, lanes)


def _moment_terms(builder, d, wv):
    wd = builder.fmul(wv, d)
    return wd, builder.fmul(wd, d)  # w d, (w d) d: the scalar chains' w[j] * d and w[j] * d * d


@intrinsic
def lane_sums(typingctx, a, quads):
    """The four chains of sum(a) (as ``resample.sum4``): (s0, s1, s2, s3)."""
    if not _contiguous_f8(a):
        return None

    def codegen(context, builder, signature, args):
        return _lane_loop(context, builder, signature, args, 1, 1, lambda b, v, s: [v[0]])

    return types.UniTuple(types.float64, 4)(a, types.intp), codegen


@intrinsic
def lane_sums_sq(typingctx, a, quads):
    """The four chains of sum(a^2) (as ``resample.sum_sq4``): (s0, s1, s2, s3)."""
    if not _contiguous_f8(a):
        return None

    def codegen(context, builder, signature, args):
        return _lane_loop(context, builder, signature, args, 1, 1, lambda b, v, s: [b.fmul(v[0], v[0])])

    return types.UniTuple(types.float64, 4)(a, types.intp), codegen


@intrinsic
def lane_moments(typingctx, row, w, ref, quads):
    """The four chains of ``estimate.weighted_moments``: (a0, a1, a2, a3, b0, b1, b2, b3), sums of
    w d and (w d) d, d = row - ref."""
    if not _contiguous_f8(row, w):
        return None

    def codegen(context, builder, signature, args):
        return _lane_loop(context, builder, signature, args, 2, 2,
                          lambda b, v, s: _moment_terms(b, b.fsub(v[0], s[0]), v[1]))

    return types.UniTuple(types.float64, 8)(row, w, types.float64, types.intp), codegen


@intrinsic
def lane_wrapped_moments(typingctx, row, w, ref, quads):
    """:func:`lane_moments` of the deviations wrapped to an angle as ``estimate._wrap`` compiles:
    d - 2 pi floor((d + pi) * INV_TWO_PI)."""
    if not _contiguous_f8(row, w):
        return None

    def codegen(context, builder, signature, args):
        floor = cgutils.get_or_insert_function(builder.module, ir.FunctionType(V4, [V4]), "llvm.floor.v4f64")

        def step(b, v, s):
            d = b.fsub(v[0], s[0])
            turns = b.call(floor, [b.fmul(b.fadd(d, _splat(math.pi)), _splat(INV_TWO_PI))])
            return _moment_terms(b, b.fsub(d, b.fmul(turns, _splat(2.0 * math.pi))), v[1])

        return _lane_loop(context, builder, signature, args, 2, 2, step)

    return types.UniTuple(types.float64, 8)(row, w, types.float64, types.intp), codegen


@intrinsic
def lane_cross(typingctx, xe, xn, w, ref_e, ref_n, quads):
    """The four chains of ``estimate.weighted_cross``: sums of (w (xe - ref_e)) (xn - ref_n)."""
    if not _contiguous_f8(xe, xn, w):
        return None

    def codegen(context, builder, signature, args):
        return _lane_loop(context, builder, signature, args, 3, 1,
                          lambda b, v, s: [b.fmul(b.fmul(v[2], b.fsub(v[0], s[0])), b.fsub(v[1], s[1]))])

    return types.UniTuple(types.float64, 4)(xe, xn, w, types.float64, types.float64, types.intp), codegen


@intrinsic
def lane_first_max(typingctx, a, quads):
    """The running maximum of ``resample.max_log_weight`` (``if a[j] > mx: mx = a[j]``, NaN passed over)
    in four lanes: (m0, m1, m2, m3, j0, j1, j2, j3), lane l's maximum over the elements j = l (mod 4)
    of the first 4 ``quads`` and the index where it first occurred (-inf and -1 for none)."""
    if not _contiguous_f8(a):
        return None

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        iv4 = ir.VectorType(i64, 4)
        arr = context.make_array(signature.args[0])(context, builder, args[0])
        best = cgutils.alloca_once_value(builder, _splat(-math.inf))
        where = cgutils.alloca_once_value(builder, ir.Constant(iv4, [-1] * 4))
        with cgutils.for_range(builder, args[1]) as loop:
            first = builder.mul(loop.index, ir.Constant(loop.index.type, 4))
            v = _load_quad(builder, arr, first)
            index = builder.add(_broadcast(builder, first, iv4), ir.Constant(iv4, [0, 1, 2, 3]))
            m = builder.load(best)
            greater = builder.fcmp_ordered(">", v, m)
            builder.store(builder.select(greater, v, m), best)
            builder.store(builder.select(greater, index, builder.load(where)), where)
        lanes = _lanes(builder, builder.load(best)) + _lanes(builder, builder.load(where))
        return context.make_tuple(builder, signature.return_type, lanes)

    return types.Tuple([types.float64] * 4 + [types.int64] * 4)(a, types.intp), codegen

