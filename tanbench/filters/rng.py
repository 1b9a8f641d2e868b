"""Random numbers for the jitted filter loops: block fills from a vectorised generator.

The loops draw their noise in blocks, a whole (rows, M) array per call, with
:func:`fill_normals` and :func:`fill_uniforms`. What they draw from is chosen by
``filter.random_numbers`` (:func:`loop_rng`):

* ``fast`` (the default): xoshiro256++ (Blackman & Vigna 2018, prng.di.unimi.it) in
  :data:`LANES` independent lanes, whose 256-bit states sit in a ``uint64`` array
  (:class:`FastRng` holds it; the loops are given the array itself). The lanes are
  stepped together, so the word loop compiles to SIMD instructions; word ``r * LANES + l``
  of a block is lane ``l``'s ``r``-th word. Normals come from those words by the ziggurat
  method (Marsaglia & Tsang 2000) with 256 layers, using independent bits of one word for
  the layer (bits 0-7), the sign (bit 8) and the abscissa (bits 12-63), so layer and value
  are not correlated (the flaw Doornik 2005 found in the original 32-bit version); the
  tables are computed here from the normal density, the base-layer edge ``r`` by
  bisection. About 1.2 % of words miss their layer's rectangle: the wedge test and the
  tail (Marsaglia's exponential rejection) then draw further words from a scalar
  xoshiro256++ stream kept after the lanes. The method is exact: the tests check moments
  and Kolmogorov-Smirnov against N(0, 1). Uniforms are the top 52 bits of a word in
  [0, 1) (one float64 mantissa: the exponent trick vectorises, an integer conversion does
  not). A generator is seeded from the run's ``SeedSequence`` on a stream of its own
  (:meth:`FastRng.from_seed`), so a run's numbers depend only on its seed, never on the
  worker count or on which process runs it;
* ``numpy``: the run's ``numpy.random.Generator``; on PCG64 (numpy's default) the fills
  step its state inline (:class:`~tanbench.numpy_stream.Pcg64Stream`): exactly the numbers the
  Generator would give, one after the other, and its state advanced as if it had drawn them.

``xoshiro_numpy``, ``lane_words_numpy``, ``normals_from_words_numpy`` and
``uniforms_from_words_numpy`` are the plain-Python references the tests check the jitted
generator against; ``fill_numpy``, made of them, is the fills' (the numbers a fill draws from
a loop's generator, and the generator's state after them), and ``fills_numpy`` replays fill after
fill from a copy of a generator's state (``resample.resample_and_regularise_numpy``).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from numba.core import cgutils, types
from numba.core.types.npytypes import NumPyRandomGeneratorType
from numba.cpython.unsafe.numbers import trailing_zeros
from numba.extending import intrinsic, overload

from tanbench.filters import FASTMATH
from tanbench.filters.vecmath import bits_float, float_bits
from tanbench.numpy_stream import Pcg64StreamType, pcg64_fill, pcg64_stream

STATE_WORDS = 4  # one xoshiro256++ state
LANES = 16  # lanes stepped together (4 AVX2 vectors of 4 words)
LANE_WORDS = STATE_WORDS * LANES  # the lanes' states
FAST_WORDS = LANE_WORDS + STATE_WORDS  # the lanes' states, then the scalar stream's
FAST_STREAM = 0xFA57  # appended to the run's spawn key: the fast generator's own stream
LAYERS = 256
MASK64 = (1 << 64) - 1
ONE_BITS = 0x3FF0000000000000  # the bits of 1.0
CHUNK = 1024  # words made per pass of the lane loop (a multiple of LANES)
CHUNK_GROUPS = CHUNK // 8  # a chunk's flags as uint64 words
BITMAP_WORDS = CHUNK // 64  # a chunk's flags as a bitmap of uint64 words
BYTE_BITS = np.uint64(0x0102040810204080)  # (a uint64 of eight 0/1 bytes times this) >> 56: their bits


# ---- ziggurat tables -------------------------------------------------------------------
def _density(x: float) -> float:
    return math.exp(-0.5 * x * x)


def _edges_for(r: float) -> tuple[np.ndarray, float, float]:
    """Layer edges x[0..LAYERS] for base edge r, the common layer area v, and the misfit
    of the top layer (its area minus v; zero at the right r)."""
    v = r * _density(r) + math.sqrt(math.pi / 2.0) * math.erfc(r / math.sqrt(2.0))
    x = np.zeros(LAYERS + 1)
    x[0] = v / _density(r)  # the base layer: a rectangle of area v including the tail
    x[1] = r
    for k in range(1, LAYERS - 1):
        y = v / x[k] + _density(x[k])
        if y >= 1.0:  # r too small: the layers overshoot the mode
            return x, v, -math.inf
        x[k + 1] = math.sqrt(-2.0 * math.log(y))
    top = x[LAYERS - 1] * (1.0 - _density(x[LAYERS - 1]))
    return x, v, top - v


def ziggurat_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(KI uint64[256], WI float64[256], FI float64[257], r) of the 256-layer normal ziggurat.

    Layer i spans abscissae [0, x[i]) between heights f(x[i]) and f(x[i+1]) (x[256] = 0);
    a 52-bit integer u gives the point x = u * WI[i], accepted at once if u < KI[i].
    """
    lo, hi = 3.0, 4.5
    for _ in range(200):  # bisection on the top layer's misfit (negative: r too small)
        mid = 0.5 * (lo + hi)
        if _edges_for(mid)[2] < 0.0:
            lo = mid
        else:
            hi = mid
    x, _, _ = _edges_for(hi)
    x[LAYERS] = 0.0
    scale = float(1 << 52)
    ki = np.array([int(scale * x[i + 1] / x[i]) for i in range(LAYERS)], dtype=np.uint64)
    wi = x[:LAYERS] / scale
    fi = np.exp(-0.5 * x * x)
    return ki, wi, fi, hi


ZIG_KI, ZIG_WI, ZIG_FI, ZIG_R = ziggurat_tables()
# the same tables for the SIMD loop of :func:`normals_from_words`: the layer edges x[i] = WI[i] 2^52
# (exact: a power-of-two scaling), so that u * WI[i] = (u 2^-52) * x[i] bit for bit, with u 2^-52
# made from the bits of u (:func:`word_uniform`) rather than by an int64 -> float64 conversion;
# the loop loads x[i] and its miss test packed in one word (:func:`packed_layers`)
ZIG_X = ZIG_WI * float(1 << 52)


def packed_layers(x, ki) -> tuple[np.ndarray, int]:
    """(uint64[256], the smallest biased exponent e0 of x): layer i's edge x[i] and a 9-bit
    floor of KI[i] in one word, for the rectangle test of :func:`_rectangle` to load with
    one gather (two cost twice as much). Bits 0-51 are x[i]'s mantissa, bits 52-54 its biased
    exponent minus e0 (x[i] > 0 spans at most 8 binades), bits 55-63 KI[i] >> 43: the word
    minus e0 2^52 in bits 52-62 is x[i] again, bit for bit, and rabs >> 43 < KI[i] >> 43
    implies rabs < KI[i] (the converse fails for about one word in 2^10)."""
    bits = x.view(np.uint64)
    e0 = int(bits.min() >> np.uint64(52))
    if (bits >> np.uint64(52)).max() - e0 >= 8:
        raise ValueError("the layer edges span more than 8 binades")
    mantissa = bits & np.uint64((1 << 52) - 1)
    packed = (ki >> np.uint64(43)) << np.uint64(55) | (bits - np.uint64(e0 << 52))
    assert np.array_equal(mantissa, packed & np.uint64((1 << 52) - 1))
    return packed, e0


ZIG_PACKED, _ZIG_E0 = packed_layers(ZIG_X, ZIG_KI)
ZIG_E0_BITS = np.uint64(_ZIG_E0 << 52)  # added to a packed word's low 55 bits: the bits of x[i]
LOW_55 = np.uint64((1 << 55) - 1)
SIGN_BIT = np.uint64(1 << 63)
# for the wedge test of :func:`normal_slow` (:func:`_under_density`)
ZIG_HALF_SQ = 0.5 * np.append(ZIG_X, 0.0) ** 2  # x[i]^2 / 2 for i = 0..256 (x[256] = 0)
SQUEEZE_MARGIN = 2.0 ** -40  # relative to FI[i + 1]: far beyond the rounding of the bounds (below 1e-14)


# ---- xoshiro256++ -------------------------------------------------------------------------
@nb.njit(cache=True, inline="always")
def _rotl(x, k):
    return (x << np.uint64(k)) | (x >> np.uint64(64 - k))


@nb.njit(cache=True, inline="always")
def _xoshiro_step(s0, s1, s2, s3):
    """xoshiro256++ on the state words (s0, s1, s2, s3): (output word, the next four words)."""
    result = _rotl(s0 + s3, 23) + s0
    t = s1 << np.uint64(17)
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    return result, s0, s1, s2, _rotl(s3, 45)


@nb.njit(cache=True, inline="always")
def _step_lane(lanes, lane):
    """Lane ``lane``'s next word, its state (words ``lane``, ``LANES + lane``, ``2 LANES + lane`` and
    ``3 LANES + lane`` of ``lanes``) stepped."""
    word, lanes[lane], lanes[LANES + lane], lanes[2 * LANES + lane], lanes[3 * LANES + lane] = \
        _xoshiro_step(lanes[lane], lanes[LANES + lane], lanes[2 * LANES + lane], lanes[3 * LANES + lane])
    return word


@nb.njit(cache=True, inline="always")
def next_u64(s):
    """One xoshiro256++ step on state ``s`` (uint64[4], updated in place); the output word."""
    result, s[0], s[1], s[2], s[3] = _xoshiro_step(s[0], s[1], s[2], s[3])
    return result


@nb.njit(cache=True, inline="always")
def uniform01(s):
    """A uniform double in [0, 1) from the scalar stream ``s``: :func:`uniform53` of its next word."""
    return uniform53(next_u64(s))


@nb.njit(cache=True, inline="always")
def uniform53(word):
    """A uniform double in [0, 1) from a word's top 53 bits times 2^-53."""
    return np.float64(word >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@nb.njit(cache=True, inline="always")
def word_uniform(w):
    """A uniform double in [0, 1) from a word's top 52 bits (bits of [1, 2), minus 1)."""
    return bits_float(np.int64((w >> np.uint64(12)) | np.uint64(ONE_BITS))) - 1.0


@intrinsic
def _stack_words(typingctx, n):
    """A pointer to ``n`` (a literal) uint64 words on the stack of the function that calls it."""
    if not isinstance(n, types.IntegerLiteral):
        return None
    size = n.literal_value

    def codegen(context, builder, signature, args):
        return cgutils.alloca_once(builder, context.get_value_type(types.uint64), size=size)

    return types.CPointer(types.uint64)(n), codegen


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def lane_words(words, out):
    """Fill ``out`` (uint64, length a multiple of LANES) from the lanes of ``words`` (a fast
    generator's state, advanced): word ``r * LANES + l`` is lane ``l``'s ``r``-th. The lanes
    are independent, so the loop over them is SIMD. The lanes' states are stepped in a copy on
    the stack, which the compiler keeps in registers (``words`` might overlap ``out``: stepped
    in place, they went through memory every round), and put back at the end."""
    lanes = nb.carray(_stack_words(LANE_WORDS), LANE_WORDS)
    for k in range(LANE_WORDS):
        lanes[k] = words[k]
    for r in range(out.shape[0] // LANES):
        base = r * LANES
        for lane in range(LANES):
            out[base + lane] = _step_lane(lanes, lane)
    for k in range(LANE_WORDS):
        words[k] = lanes[k]


# The miss path (:func:`normal_slow`, :func:`_normal_tail`) is compiled with FASTMATH, the flags
# numba gave it when it first compiled it as a callee of the FASTMATH rectangle pass (a callee
# without flags of its own inherits its caller's): stated here, so that its numbers do not depend
# on which function numba happened to compile first. With "arcp" the division by r is a
# multiplication by 1 / r. Both are inlined (numba's inliner) into :func:`finish_flagged`, also
# FASTMATH, where the scalar stream is then kept in registers.
@nb.njit(cache=True, fastmath=FASTMATH, inline="always")
def _normal_tail(s, negative):
    """A normal beyond the base edge r (Marsaglia's exponential rejection), with the sign."""
    while True:
        xx = -math.log1p(-uniform01(s)) / ZIG_R
        yy = -math.log1p(-uniform01(s))
        if yy + yy > xx * xx:
            return -(ZIG_R + xx) if negative else ZIG_R + xx


@nb.njit(cache=True, inline="always")
def _under_density(i, x, y):
    """``y < math.exp(-0.5 * x * x)`` for a point of layer i's wedge (1 <= i <= 255, x[i+1] <= x < x[i]),
    answered without exp unless y is within ``SQUEEZE_MARGIN`` FI[i+1] of a bound: with
    t = (x[i+1]^2 - x^2) / 2 (in (-0.73, 0]), f(x) = FI[i+1] e^t and
    1 + t + t^2/2 + t^3/6 <= e^t <= 1 + t + t^2/2. The rounding of t, of the bounds, of FI and of
    exp is below 1e-14 FI[i+1], so outside the margin the answer is the one exp would give."""
    below, above = _wedge_bounds(i, x, y)
    if below:
        return True
    if above:
        return False
    return y < math.exp(-0.5 * x * x)


@nb.njit(cache=True, inline="always")
def _wedge_bounds(i, x, y):
    """(y below the lower bound of f(x) by more than the margin, y at or above the upper bound plus the margin)
    for :func:`_under_density`'s test: exp is needed only when both are False."""
    t = ZIG_HALF_SQ[i + 1] - 0.5 * x * x
    upper = 1.0 + t * (1.0 + 0.5 * t)
    lower = upper + t * t * t * (1.0 / 6.0)
    return y < ZIG_FI[i + 1] * (lower - SQUEEZE_MARGIN), y >= ZIG_FI[i + 1] * (upper + SQUEEZE_MARGIN)


@nb.njit(cache=True, fastmath=FASTMATH, inline="always")
def normal_slow(s, u):
    """The rest of the ziggurat for a word ``u`` that missed its layer's rectangle (about 1.2 %
    of words): the tail, a wedge test, or new words from the scalar stream ``s`` until one
    is accepted."""
    while True:
        i = np.intp(u & np.uint64(0xFF))
        negative = (u >> np.uint64(8)) & np.uint64(1)
        rabs = u >> np.uint64(12)
        x = np.float64(rabs) * ZIG_WI[i]
        if rabs < ZIG_KI[i]:
            return -x if negative else x
        if i == 0:
            return _normal_tail(s, negative)
        if _under_density(i, x, ZIG_FI[i] + uniform01(s) * (ZIG_FI[i + 1] - ZIG_FI[i])):
            return -x if negative else x
        u = next_u64(s)


@nb.njit(cache=True, inline="always")
def _finish_word(s, u):
    """:func:`normal_slow` of a flagged word ``u`` (the same number, the same words drawn from ``s``),
    its common outcomes chosen without a branch: ``u`` in its rectangle after all, ``u``'s wedge
    test decided by the bounds of :func:`_under_density` (accepted, or rejected and the next word
    of ``s`` in its rectangle). The two words they may draw are made in advance and the state put
    back to the one its outcome leaves; anything else (the tail, a test within the margin, a
    second miss, about 2 % of flagged words) is :func:`normal_slow` from the start. The same
    expressions as :func:`normal_slow`, :func:`uniform01` and :func:`_under_density`, so the same
    bits. Written without branches but the rare one (LLVM still branches on ``inside``, about 7 %
    of flagged words); the wedge's accept or reject, about half and half, had a branch mispredicted
    for about every second flagged word."""
    i = np.intp(u & np.uint64(0xFF))
    rabs = u >> np.uint64(12)
    x = np.float64(rabs) * ZIG_WI[i]
    s0, s1, s2, s3 = s[0], s[1], s[2], s[3]
    drawn, a0, a1, a2, a3 = _xoshiro_step(s0, s1, s2, s3)  # the wedge test's uniform
    v, b0, b1, b2, b3 = _xoshiro_step(a0, a1, a2, a3)  # the next word, if rejected
    y = ZIG_FI[i] + uniform53(drawn) * (ZIG_FI[i + 1] - ZIG_FI[i])
    below, above = _wedge_bounds(i, x, y)
    k = np.intp(v & np.uint64(0xFF))
    vabs = v >> np.uint64(12)
    xv = np.float64(vabs) * ZIG_WI[k]
    inside = rabs < ZIG_KI[i]
    if not (inside | ((i != 0) & (below | (above & (vabs < ZIG_KI[k]))))):  # bitwise: no branches
        return normal_slow(s, u)
    first = inside | below
    z = x if first else xv
    negative = ((u if first else v) >> np.uint64(8)) & np.uint64(1)
    one = below & ~inside  # the state its outcome leaves: no word drawn, one, or two
    s[0] = s0 if inside else (a0 if one else b0)
    s[1] = s1 if inside else (a1 if one else b1)
    s[2] = s2 if inside else (a2 if one else b2)
    s[3] = s3 if inside else (a3 if one else b3)
    return -z if negative else z


@nb.njit(cache=True, inline="always")
def _rectangle(u):
    """(the normal of word ``u`` if it lies in its layer's rectangle, 1 if it may not: uint8)
    without a branch. The rectangle's point u * WI[i] (u the 52-bit abscissa) is computed as
    (u 2^-52) * x[i]: the same bits; x[i] and the miss test come from one table word
    (:data:`ZIG_PACKED`), whose 9-bit test flags every miss and, rarely, a word that is not one
    (:func:`normal_slow` then returns the same point at once, drawing nothing). The sign is
    applied to the bits (a sign flip is exact)."""
    packed = ZIG_PACKED[np.intp(u & np.uint64(0xFF))]
    x = bits_float(np.int64((packed & LOW_55) + ZIG_E0_BITS))
    sign = (u << np.uint64(55)) & SIGN_BIT
    flag = np.uint8(0) if (u | LOW_55) < packed else np.uint8(1)  # u >> 55 < packed >> 55
    return bits_float(float_bits(word_uniform(u) * x) ^ np.int64(sign)), flag


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def finish_flagged(w, s, out, bits, listed):
    """Replace ``out[j]`` by :func:`normal_slow` of word ``w[j]`` (:func:`_finish_word`) wherever bit
    ``j % 64`` of ``bits[j // 64]`` (uint64, none set beyond ``out``; emptied) is set, in order of j,
    from the scalar stream ``s``. The bitmap's nonzero words are listed (in ``listed``, intp, as long
    as ``bits``) and the flagged words taken lowest bit first in one loop with no other branch: the
    same numbers as testing every word again, without doing so."""
    stream = nb.carray(_stack_words(STATE_WORDS), STATE_WORDS)  # the scalar stream, kept in registers
    for k in range(STATE_WORDS):
        stream[k] = s[k]
    count = 0
    for q in range(bits.shape[0]):  # the bitmap's nonzero words, no branch
        listed[count] = q
        count += bits[q] != 0
    k = 0
    while k < count:  # lowest bit of the k-th listed word: taken, cleared; k moves on once it is empty
        q = listed[k]
        found = bits[q]
        j = 64 * q + np.intp(trailing_zeros(found))
        out[j] = _finish_word(stream, w[j])
        found &= found - np.uint64(1)
        bits[q] = found
        k += found == 0
    for k in range(STATE_WORDS):
        s[k] = stream[k]


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def normals_from_words(w, s, out):
    """Ziggurat normals into ``out`` from the words ``w`` (one each), the rare misses finished
    from the scalar stream ``s``: the rectangles (:func:`_rectangle`, a SIMD loop: no call, no
    branch), their flags a bitmap, then the flagged words finished in order (:func:`finish_flagged`)."""
    n = out.shape[0]
    bits = np.zeros((n + 63) // 64, dtype=np.uint64)
    for j in range(n):
        out[j], flag = _rectangle(w[j])
        bits[j >> 6] |= np.uint64(flag) << np.uint64(j & 63)
    finish_flagged(w, s, out, bits, np.empty(bits.shape[0], dtype=np.intp))


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def lane_normals(words, s, out):
    """Normals into ``out`` (at most CHUNK) from the lanes of ``words`` (:func:`lane_words`, the lanes
    advanced by ``out``'s length rounded up to a multiple of LANES), the flagged words finished from
    the scalar stream ``s``: :func:`normals_from_words` of :func:`lane_words`' words, in one pass. Each
    round's words are used as they are made (a pass of their own cost a store and a load of each)
    and kept on the stack for :func:`finish_flagged`, with their flags: bytes from the SIMD loop,
    each round's 16 made a 16-bit mask of the bitmap. Words of a last round beyond ``out`` are
    dropped."""
    w = nb.carray(_stack_words(CHUNK), CHUNK)
    bits = nb.carray(_stack_words(BITMAP_WORDS), BITMAP_WORDS)
    listed = nb.carray(_stack_words(BITMAP_WORDS), BITMAP_WORDS).view(np.intp)
    lanes = nb.carray(_stack_words(LANE_WORDS), LANE_WORDS)
    made = nb.carray(_stack_words(LANES), LANES)  # a round's words
    eights = nb.carray(_stack_words(CHUNK_GROUPS), CHUNK_GROUPS)  # the flags, as bytes
    flags = eights.view(np.uint8)
    for k in range(LANE_WORDS):
        lanes[k] = words[k]
    for q in range(BITMAP_WORDS):
        bits[q] = np.uint64(0)
    n = out.shape[0]
    for r in range(n // LANES):
        base = r * LANES
        for lane in range(LANES):
            made[lane] = _step_lane(lanes, lane)
        for lane in range(LANES):
            u = made[lane]
            w[base + lane] = u
            out[base + lane], flags[base + lane] = _rectangle(u)
        low = (eights[base >> 3] * BYTE_BITS) >> np.uint64(56)  # the round's 16 flags: a 16-bit mask
        high = (eights[(base >> 3) + 1] * BYTE_BITS) >> np.uint64(56)
        bits[base >> 6] |= (low | high << np.uint64(8)) << np.uint64(base & 63)
    base = n - n % LANES
    if base < n:  # a last round, partly used
        for lane in range(LANES):
            w[base + lane] = _step_lane(lanes, lane)
        for j in range(base, n):
            out[j], flag = _rectangle(w[j])
            bits[j >> 6] |= np.uint64(flag) << np.uint64(j & 63)
    for k in range(LANE_WORDS):
        words[k] = lanes[k]
    used = (n + 63) // 64
    finish_flagged(w, s, out, bits[:used], listed[:used])


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def uniforms_from_words(w, low, high, out):
    """``low + (high - low) u`` into ``out``, u uniform in [0, 1) from the words ``w``."""
    scale = high - low
    for j in range(out.shape[0]):
        out[j] = low + scale * word_uniform(w[j])


@nb.njit(cache=True)
def _fast_fill(words, out, normal, low, high):
    """Fill the 1-D ``out`` from the fast generator's state ``words``: normals, or uniforms
    in [low, high). Words are made in chunks (a multiple of LANES): normals by :func:`lane_normals`,
    uniforms into a buffer on the stack first; words of a chunk's last round beyond ``out`` are
    dropped."""
    buf = nb.carray(_stack_words(CHUNK), CHUNK)
    scalar = words[STATE_WORDS * LANES:]
    n = out.shape[0]
    start = 0
    while start < n:
        size = min(CHUNK, n - start)
        made = (size + LANES - 1) // LANES * LANES
        if normal:
            lane_normals(words, scalar, out[start:start + size])
        else:
            lane_words(words, buf[:made])
            uniforms_from_words(buf[:size], low, high, out[start:start + size])
        start += size


# ---- numpy's own stream (``random_numbers: numpy``): tanbench/numpy_stream.py, or for a Generator not on
# PCG64, the Generator itself
@nb.njit(cache=True)
def _generator_fill(rng, out, normal, low, high):
    """Normals or uniforms from a numba-typed numpy Generator, one draw at a time."""
    for j in range(out.shape[0]):
        out[j] = rng.standard_normal() if normal else rng.uniform(low, high)


# ---- the fills the loops call -------------------------------------------------------------------
def _fill(rng, out, normal, low, high):
    """Fill ``out`` (any shape, C-contiguous) with standard normals (``normal``) or uniforms in
    [low, high) from ``rng``: a fast generator's state words, a :class:`Pcg64Stream` or a
    numpy Generator. Callable from jitted and from plain Python code."""
    _fill_jit(rng, out, normal, low, high)


@overload(_fill)
def _ol_fill(rng, out, normal, low, high):
    if isinstance(rng, types.Array) and rng.dtype == types.uint64:
        return lambda rng, out, normal, low, high: _fast_fill(rng, out.reshape(-1), normal, low, high)
    if isinstance(rng, Pcg64StreamType):
        return lambda rng, out, normal, low, high: pcg64_fill(rng.state, out.reshape(-1), normal, low, high)
    if isinstance(rng, NumPyRandomGeneratorType):
        return lambda rng, out, normal, low, high: _generator_fill(rng, out.reshape(-1), normal, low, high)
    return None


@nb.njit(cache=True)
def _fill_jit(rng, out, normal, low, high):
    _fill(rng, out, normal, low, high)


@nb.njit(cache=True)
def fill_normals(rng, out):
    """Standard normals into ``out`` (any shape, C-contiguous), in memory order."""
    _fill(rng, out.reshape(-1), True, 0.0, 1.0)  # flat: the fill compiles once, whatever ``out``'s shape


@nb.njit(cache=True)
def fill_uniforms(rng, out, low=0.0, high=1.0):
    """Uniforms in [low, high) into ``out`` (any shape, C-contiguous), in memory order."""
    _fill(rng, out.reshape(-1), False, low, high)


# ---- the generator objects -----------------------------------------------------------------
class FastRng:
    """The fast generator's state (``state``: uint64[FAST_WORDS], the lanes then the scalar
    stream) with plain-Python draws; the jitted loops are given ``state`` itself."""

    def __init__(self, state):
        state = np.ascontiguousarray(state, dtype=np.uint64).copy()
        if state.shape != (FAST_WORDS,):
            raise ValueError(f"a FastRng state is {FAST_WORDS} uint64 words, got shape {state.shape}")
        for k in range(LANES + 1):
            words = state[k:STATE_WORDS * LANES:LANES] if k < LANES else state[STATE_WORDS * LANES:]
            if not words.any():
                raise ValueError("no xoshiro256++ state of a FastRng may be all zeros")
        self.state = state

    @classmethod
    def from_seed(cls, seed: np.random.SeedSequence) -> "FastRng":
        """The generator of a run's seed, on its own stream (``FAST_STREAM`` added to the spawn key)."""
        own = np.random.SeedSequence(seed.entropy, spawn_key=tuple(seed.spawn_key) + (FAST_STREAM,),
                                     pool_size=seed.pool_size)
        state = own.generate_state(FAST_WORDS, np.uint64)
        for k in range(LANES):  # probability 2^-256 each: xoshiro's one forbidden state
            if not state[k:STATE_WORDS * LANES:LANES].any():
                state[k] = 1
        if not state[STATE_WORDS * LANES:].any():
            state[-1] = 1
        return cls(state)

    def standard_normal(self, size: int | None = None):
        out = np.empty(1 if size is None else int(size))
        fill_normals(self.state, out)
        return float(out[0]) if size is None else out

    def random(self, size: int | None = None):
        out = np.empty(1 if size is None else int(size))
        fill_uniforms(self.state, out)
        return float(out[0]) if size is None else out


def loop_rng(rng: np.random.Generator, random_numbers: str):
    """What a jitted loop draws from: for ``fast`` the state words of a :class:`FastRng` seeded
    from ``rng``'s SeedSequence (its own stream); for ``numpy`` ``rng``'s own stream (a
    :class:`Pcg64Stream` on it, or ``rng`` itself if it is not on PCG64)."""
    if random_numbers == "fast":
        return FastRng.from_seed(rng.bit_generator.seed_seq).state
    if random_numbers == "numpy":
        stream = pcg64_stream(rng)
        return rng if stream is None else stream
    raise ValueError(f"unknown random_numbers {random_numbers!r}")


def rng_state(rng):
    """A copy of the state of what a jitted loop draws from (:func:`loop_rng`: a fast generator's state
    words, a :class:`Pcg64Stream` or a numpy Generator), for :func:`set_rng_state` to put back."""
    if isinstance(rng, np.ndarray):
        return rng.copy()
    return rng.bit_generator.state


def set_rng_state(rng, state) -> None:
    """Put back a state taken by :func:`rng_state`, in place (a :class:`Pcg64Stream` keeps its Generator's
    memory: setting the bit generator's state writes into it)."""
    if isinstance(rng, np.ndarray):
        rng[...] = state
    else:
        rng.bit_generator.state = state


# ---- plain-Python references -----------------------------------------------------------------
def xoshiro_numpy(state, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Reference xoshiro256++ on Python integers: (n output words, the new state)."""
    s = [int(v) for v in np.asarray(state, dtype=np.uint64)]

    def rotl(x, k):
        return ((x << k) | (x >> (64 - k))) & MASK64

    out = np.empty(n, dtype=np.uint64)
    for j in range(n):
        out[j] = (rotl((s[0] + s[3]) & MASK64, 23) + s[0]) & MASK64
        t = (s[1] << 17) & MASK64
        s[2] ^= s[0]
        s[3] ^= s[1]
        s[1] ^= s[2]
        s[0] ^= s[3]
        s[2] ^= t
        s[3] = rotl(s[3], 45)
    return out, np.array(s, dtype=np.uint64)


def lane_words_numpy(words, rounds: int) -> tuple[np.ndarray, np.ndarray]:
    """Reference of :func:`lane_words`: (rounds * LANES words, the new state words)."""
    words = np.asarray(words, dtype=np.uint64).copy()
    out = np.empty((rounds, LANES), dtype=np.uint64)
    for lane in range(LANES):
        out[:, lane], new = xoshiro_numpy(words[lane:STATE_WORDS * LANES:LANES], rounds)
        words[lane:STATE_WORDS * LANES:LANES] = new
    return out.reshape(-1), words


def normals_from_words_numpy(w, scalar_state) -> np.ndarray:
    """Reference of :func:`normals_from_words` (``scalar_state``: the scalar stream, not changed)."""
    return normals_and_state_numpy(w, scalar_state)[0]


def normals_and_state_numpy(w, scalar_state) -> tuple[np.ndarray, np.ndarray]:
    """:func:`normals_from_words_numpy` and the scalar stream's state after it (``scalar_state`` not changed)."""
    state = np.asarray(scalar_state, dtype=np.uint64).copy()

    def word():
        nonlocal state
        out, state = xoshiro_numpy(state, 1)
        return int(out[0])

    def uni():
        return (word() >> 11) * 2.0**-53

    out = np.empty(len(w))
    for j, u in enumerate(int(v) for v in w):
        while True:
            i, negative, rabs = u & 0xFF, (u >> 8) & 1, u >> 12
            x = rabs * float(ZIG_WI[i])
            if rabs < int(ZIG_KI[i]):
                break
            if i == 0:
                while True:
                    xx = -math.log1p(-uni()) * (1.0 / ZIG_R)  # as compiled (:func:`_normal_tail`)
                    yy = -math.log1p(-uni())
                    if yy + yy > xx * xx:
                        break
                x = ZIG_R + xx
                break
            if ZIG_FI[i] + uni() * (ZIG_FI[i + 1] - ZIG_FI[i]) < math.exp(-0.5 * x * x):
                break
            u = word()
        out[j] = -x if negative else x
    return out, state


def uniforms_from_words_numpy(w, low: float = 0.0, high: float = 1.0) -> np.ndarray:
    """Reference of :func:`uniforms_from_words`."""
    u = (np.asarray(w, dtype=np.uint64) >> np.uint64(12)).astype(np.float64) * 2.0**-52
    return low + (high - low) * u


def fill_numpy(rng, shape, normal: bool, low: float = 0.0, high: float = 1.0) -> np.ndarray:
    """Plain-numpy reference of the fills (:func:`fill_normals`, :func:`fill_uniforms`): an array of
    ``shape`` (C order) of standard normals (``normal``) or uniforms in [low, high), drawn from ``rng``
    as a jitted fill draws them, and ``rng`` advanced as the fill advances it (in place). ``rng`` is what
    the loops draw from (:func:`loop_rng`): a fast generator's state words, made into the numbers by
    :func:`lane_words_numpy`, :func:`normals_and_state_numpy` and :func:`uniforms_from_words_numpy` in
    chunks of ``CHUNK`` as :func:`_fast_fill` makes them (each chunk's words rounded up to whole rounds of
    the lanes, the rest dropped); or numpy's stream (a :class:`~tanbench.numpy_stream.Pcg64Stream` or a
    Generator), drawn by the Generator itself."""
    size = int(np.prod(shape, dtype=np.int64))
    if isinstance(rng, np.ndarray):
        if rng.dtype != np.uint64 or rng.shape != (FAST_WORDS,):
            raise ValueError(f"a fast generator's state is {FAST_WORDS} uint64 words")
        out = np.empty(size)
        words = rng.copy()
        for start in range(0, size, CHUNK):
            part = min(CHUNK, size - start)
            made, words[:LANE_WORDS] = lane_words_numpy(words[:LANE_WORDS], (part + LANES - 1) // LANES)
            if normal:
                out[start:start + part], words[LANE_WORDS:] = normals_and_state_numpy(made[:part], words[LANE_WORDS:])
            else:
                out[start:start + part] = uniforms_from_words_numpy(made[:part], low, high)
        rng[...] = words
        return out.reshape(shape)
    generator = getattr(rng, "generator", rng)  # a Pcg64Stream draws what its Generator draws
    if not isinstance(generator, np.random.Generator):
        raise TypeError(f"cannot draw from {type(rng).__name__}: a fast generator's state words, a Pcg64Stream "
                        "or a numpy Generator")
    if normal:
        return generator.standard_normal(size).reshape(shape)
    return generator.uniform(low, high, size).reshape(shape)


def fills_numpy(rng):
    """A plain-Python replay of the fills from ``rng`` (what a jitted loop draws from, as for
    :func:`fill_numpy`) that leaves ``rng`` alone: a function ``draw(n, normal)`` giving the next ``n``
    numbers that :func:`fill_normals` (``normal``) or :func:`fill_uniforms` would give, fill after fill,
    by :func:`fill_numpy` on a copy of its state."""
    if isinstance(rng, np.ndarray):
        copy = np.asarray(rng, dtype=np.uint64).copy()
    else:
        generator = getattr(rng, "generator", rng)
        twin = type(generator.bit_generator)()
        twin.state = generator.bit_generator.state
        copy = np.random.Generator(twin)
    return lambda n, normal: fill_numpy(copy, n, normal)
