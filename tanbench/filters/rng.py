"""A fast random number generator for the jitted filter loops (``filter.random_numbers: fast``).

The loops draw their noise as ``rng.standard_normal()``, ``rng.random()`` and
``rng.uniform(low, high)``. With ``random_numbers: numpy`` (the neutral value) ``rng``
is the run's ``numpy.random.Generator``; numba then calls the bit generator through a
function pointer for every 64-bit word. With ``fast`` it is a :class:`FastRng`, a
numba type with the same three methods, compiled inline into the loops:

* xoshiro256++ (Blackman & Vigna 2018, prng.di.unimi.it): 256 bits of state in a
  ``uint64[4]`` array, one 64-bit word per step;
* uniforms as the top 53 bits of a word times 2^-53, in [0, 1) (as numpy's
  ``next_double``);
* standard normals by the ziggurat method (Marsaglia & Tsang 2000) with 256 layers,
  using independent bits of one word for the layer (bits 0-7), the sign (bit 8) and
  the abscissa (bits 12-63, 52 bits), so layer and value are not correlated (the flaw
  Doornik 2005 found in the original 32-bit version). The tables are computed here
  from the normal density, the base-layer edge ``r`` by bisection; the tail beyond
  ``r`` is sampled exactly by Marsaglia's exponential rejection. The method is exact:
  the tests check moments and a Kolmogorov-Smirnov test against N(0, 1).

A ``FastRng`` is seeded from the run's ``SeedSequence`` (:meth:`FastRng.from_seed`) on
a stream of its own, so a run's numbers depend only on its seed, never on the worker
count or on which process runs it. ``xoshiro_numpy`` and ``normal_numpy`` are the
plain-Python references the tests check the jitted generator against.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import (NativeValue, intrinsic, make_attribute_wrapper, models, overload, overload_method,
                             register_model, typeof_impl, unbox)
from numba.np.random._constants import fi_double, ki_double, wi_double, ziggurat_nor_inv_r, ziggurat_nor_r

STATE_WORDS = 4
FAST_STREAM = 0xFA57  # appended to the run's spawn key: the fast generator's own stream
LAYERS = 256
MASK64 = (1 << 64) - 1


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


# ---- the jitted generator ----------------------------------------------------------------
@nb.njit(cache=True, inline="always")
def _rotl(x, k):
    return (x << np.uint64(k)) | (x >> np.uint64(64 - k))


@nb.njit(cache=True, inline="always")
def next_u64(s):
    """One xoshiro256++ step on state ``s`` (uint64[4], updated in place); the output word."""
    s0, s1, s2, s3 = s[0], s[1], s[2], s[3]
    result = _rotl(s0 + s3, 23) + s0
    t = s1 << np.uint64(17)
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = _rotl(s3, 45)
    s[0], s[1], s[2], s[3] = s0, s1, s2, s3
    return result


@nb.njit(cache=True, inline="always")
def uniform01(s):
    """A uniform double in [0, 1): the word's top 53 bits times 2^-53."""
    return np.float64(next_u64(s) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@nb.njit(cache=True)
def _normal_tail(s, negative):
    """A normal beyond the base edge r (Marsaglia's exponential rejection), with the sign."""
    while True:
        xx = -math.log1p(-uniform01(s)) / ZIG_R
        yy = -math.log1p(-uniform01(s))
        if yy + yy > xx * xx:
            return -(ZIG_R + xx) if negative else ZIG_R + xx


@nb.njit(cache=True)
def _normal_slow(s, u):
    """The rest of the ziggurat for a word ``u`` that missed its layer's rectangle (about 1 %
    of draws): the tail, a wedge test, or new words until one is accepted."""
    while True:
        i = np.intp(u & np.uint64(0xFF))
        negative = (u >> np.uint64(8)) & np.uint64(1)
        rabs = u >> np.uint64(12)
        x = np.float64(rabs) * ZIG_WI[i]
        if rabs < ZIG_KI[i]:
            return -x if negative else x
        if i == 0:
            return _normal_tail(s, negative)
        if ZIG_FI[i] + uniform01(s) * (ZIG_FI[i + 1] - ZIG_FI[i]) < math.exp(-0.5 * x * x):
            return -x if negative else x
        u = next_u64(s)


@nb.njit(cache=True, inline="always")
def standard_normal(s):
    """A standard normal by the 256-layer ziggurat on state ``s``: the fast path (one word,
    one table compare) is inlined into the caller; the rest is :func:`_normal_slow`."""
    u = next_u64(s)
    i = np.intp(u & np.uint64(0xFF))
    rabs = u >> np.uint64(12)
    if rabs < ZIG_KI[i]:
        x = np.float64(rabs) * ZIG_WI[i]
        return -x if (u >> np.uint64(8)) & np.uint64(1) else x
    return _normal_slow(s, u)


@nb.njit(cache=True)
def fill_u64(s, out):
    for j in range(out.shape[0]):
        out[j] = next_u64(s)


@nb.njit(cache=True)
def fill_uniform(s, out):
    for j in range(out.shape[0]):
        out[j] = uniform01(s)


@nb.njit(cache=True)
def fill_standard_normal(s, out):
    for j in range(out.shape[0]):
        out[j] = standard_normal(s)


# ---- the generator object the loops are given ----------------------------------------------
class FastRng:
    """xoshiro256++ with a ziggurat normal; in jitted code it offers ``standard_normal()``,
    ``random()``, ``uniform(low, high)`` and ``normal(loc, scale)`` like a numpy Generator."""

    def __init__(self, state):
        state = np.ascontiguousarray(state, dtype=np.uint64).copy()
        if state.shape != (STATE_WORDS,):
            raise ValueError(f"a FastRng state is {STATE_WORDS} uint64 words, got shape {state.shape}")
        if not state.any():
            raise ValueError("a FastRng state must not be all zeros")
        self.state = state
        self._address = state.ctypes.data  # what jitted code sees (no reference counting per draw)

    @classmethod
    def from_seed(cls, seed: np.random.SeedSequence) -> "FastRng":
        """The generator of a run's seed, on its own stream (``FAST_STREAM`` added to the spawn key)."""
        own = np.random.SeedSequence(seed.entropy, spawn_key=tuple(seed.spawn_key) + (FAST_STREAM,),
                                     pool_size=seed.pool_size)
        state = own.generate_state(STATE_WORDS, np.uint64)
        if not state.any():  # probability 2^-256; xoshiro's one forbidden state
            state[0] = 1
        return cls(state)

    # plain-Python use (tests, set-up code): the same streams as inside the loops
    def standard_normal(self, size: int | None = None):
        out = np.empty(1 if size is None else int(size))
        fill_standard_normal(self.state, out)
        return float(out[0]) if size is None else out

    def random(self, size: int | None = None):
        out = np.empty(1 if size is None else int(size))
        fill_uniform(self.state, out)
        return float(out[0]) if size is None else out

    def uniform(self, low: float = 0.0, high: float = 1.0, size: int | None = None):
        return low + (high - low) * self.random(size)

    def normal(self, loc: float = 0.0, scale: float = 1.0, size: int | None = None):
        return loc + scale * self.standard_normal(size)


class FastRngType(types.Type):
    def __init__(self):
        super().__init__(name="FastRng")


fast_rng_type = FastRngType()
_STATE_POINTER = types.CPointer(types.uint64)


@typeof_impl.register(FastRng)
def _typeof_fast_rng(val, c):
    return fast_rng_type


@register_model(FastRngType)
class _FastRngModel(models.StructModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, [("state", _STATE_POINTER)])


def _unbox_state_words(typ, obj, c):
    """A stream's native form is a pointer to its state words (``obj._address``), borrowed for
    the call (the Python object keeps the memory alive; draws advance it). A pointer, not an
    array, so a draw costs no reference counting."""
    addr_obj = c.pyapi.object_getattr_string(obj, "_address")
    addr = c.pyapi.long_as_voidptr(addr_obj)
    c.pyapi.decref(addr_obj)
    rng = cgutils.create_struct_proxy(typ)(c.context, c.builder)
    rng.state = c.builder.bitcast(addr, c.context.get_value_type(_STATE_POINTER))
    return NativeValue(rng._getvalue(), is_error=cgutils.is_not_null(c.builder, c.pyapi.err_occurred()))


def _register_draws(stream_type, draw_normal, draw_double) -> None:
    """Give ``stream_type`` (a numba type holding ``state``, a pointer to its words) the
    methods the loops call on a numpy Generator, drawing with ``draw_normal(words)`` and
    ``draw_double(words)``; its Python objects unbox by :func:`_unbox_state_words`."""
    make_attribute_wrapper(stream_type, "state", "state")
    unbox(stream_type)(_unbox_state_words)

    @overload_method(stream_type, "standard_normal")
    def _ol_standard_normal(rng):
        def impl(rng):
            return draw_normal(rng.state)
        return impl

    @overload_method(stream_type, "random")
    def _ol_random(rng):
        def impl(rng):
            return draw_double(rng.state)
        return impl

    @overload_method(stream_type, "uniform")
    def _ol_uniform(rng, low=0.0, high=1.0):
        def impl(rng, low=0.0, high=1.0):
            scaled = (high - low) * draw_double(rng.state)
            return low + scaled
        return impl

    @overload_method(stream_type, "normal")
    def _ol_normal(rng, loc=0.0, scale=1.0):
        def impl(rng, loc=0.0, scale=1.0):
            scaled = scale * draw_normal(rng.state)
            return loc + scaled
        return impl


_register_draws(FastRngType, standard_normal, uniform01)


# ---- numpy's own stream, drawn inline (``random_numbers: numpy``) -------------------------------
# A numpy Generator inside numba costs an indirect call into the bit generator per 64-bit
# word. For a Generator on PCG64 (numpy's default), :class:`Pcg64Stream` steps the very
# same PCG64 state in place from jitted code (128-bit LCG, XSL-RR output, as numpy's
# pcg64.h) and applies the same transformations numba's Generator methods apply (numpy's
# 256-layer ziggurat and tables, uniforms as 53-bit words): the same numbers in the same
# order, the Generator's state advanced exactly as if it had drawn them itself.
PCG64_MULTIPLIER = (2549297995355413924 << 64) + 4865540595714422341


@intrinsic
def _pcg64_next(typingctx, words):
    """One PCG64 step on ``words`` (uint64[4]: state low, high, increment low, high); the output."""
    sig = types.uint64(words)

    def codegen(context, builder, signature, args):
        ptr = args[0]
        i64, i128 = ir.IntType(64), ir.IntType(128)
        slots = [builder.gep(ptr, [ir.Constant(ir.IntType(32), k)]) for k in range(4)]
        lo, hi, inc_lo, inc_hi = (builder.load(p) for p in slots)

        def wide(low, high):
            return builder.or_(builder.zext(low, i128), builder.shl(builder.zext(high, i128), ir.Constant(i128, 64)))

        state = builder.add(builder.mul(wide(lo, hi), ir.Constant(i128, PCG64_MULTIPLIER)), wide(inc_lo, inc_hi))
        new_lo = builder.trunc(state, i64)
        new_hi = builder.trunc(builder.lshr(state, ir.Constant(i128, 64)), i64)
        builder.store(new_lo, slots[0])
        builder.store(new_hi, slots[1])
        word = builder.xor(new_hi, new_lo)
        rot = builder.lshr(new_hi, ir.Constant(i64, 58))
        back = builder.and_(builder.neg(rot), ir.Constant(i64, 63))
        return builder.or_(builder.lshr(word, rot), builder.shl(word, back))

    return sig, codegen


@nb.njit(cache=True, inline="always")
def pcg64_double(w):
    """numpy's next_double: the top 53 bits of a word times 2^-53."""
    return np.float64(_pcg64_next(w) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@nb.njit(cache=True, inline="always")
def _pcg64_ziggurat_draw(w):
    """One word of numpy's ziggurat: (layer ``idx``, the 52-bit magnitude ``rabs``, the signed
    candidate ``x``); ``x`` is the normal if ``rabs < ki_double[idx]``."""
    r = _pcg64_next(w)
    idx = np.intp(r & np.uint64(0xFF))
    r >>= np.uint64(8)
    rabs = (r >> np.uint64(1)) & np.uint64(0x000FFFFFFFFFFFFF)
    x = np.float64(rabs) * wi_double[idx]
    if r & np.uint64(1):
        x = -x
    return idx, rabs, x


@nb.njit(cache=True)
def _pcg64_normal_slow(w, idx, rabs, x):
    """numpy's ziggurat beyond the rectangle test: the tail (layer 0) or the wedge, then new words."""
    while True:
        if idx == 0:
            while True:
                xx = -ziggurat_nor_inv_r * np.log1p(-pcg64_double(w))
                yy = -np.log1p(-pcg64_double(w))
                if yy + yy > xx * xx:
                    return -(ziggurat_nor_r + xx) if (rabs >> np.uint64(8)) & np.uint64(1) else ziggurat_nor_r + xx
        elif (fi_double[idx - 1] - fi_double[idx]) * pcg64_double(w) + fi_double[idx] < np.exp(-0.5 * x * x):
            return x
        idx, rabs, x = _pcg64_ziggurat_draw(w)
        if rabs < ki_double[idx]:
            return x


@nb.njit(cache=True, inline="always")
def pcg64_standard_normal(w):
    """numpy's standard normal (random_standard_normal) on the PCG64 words ``w``; the fast
    path (one word, one table compare) inline."""
    idx, rabs, x = _pcg64_ziggurat_draw(w)
    if rabs < ki_double[idx]:
        return x
    return _pcg64_normal_slow(w, idx, rabs, x)


def _pcg64_words_address(generator: np.random.Generator) -> int | None:
    """Address of the PCG64 state and increment words of ``generator``, or None if it is not a
    PCG64 with the native 128-bit layout (checked against the state numpy reports)."""
    import ctypes

    bitgen = generator.bit_generator
    if type(bitgen) is not np.random.PCG64:
        return None
    pcg = ctypes.c_void_p.from_address(bitgen.ctypes.state.value).value  # pcg64_state.pcg_state
    words = (ctypes.c_uint64 * 4).from_address(pcg)
    state = bitgen.state["state"]
    if (words[0] | words[1] << 64, words[2] | words[3] << 64) != (state["state"], state["inc"]):
        return None
    return pcg


class Pcg64Stream:
    """A numpy Generator on PCG64, as the jitted loops draw from it: ``standard_normal()``,
    ``random()``, ``uniform(low, high)`` and ``normal(loc, scale)`` give exactly the numbers
    the Generator would, and advance its state. Holds the Generator (whose memory it uses)."""

    def __init__(self, generator: np.random.Generator):
        address = _pcg64_words_address(generator)
        if address is None:
            raise ValueError("Pcg64Stream needs a numpy Generator on PCG64")
        self.generator = generator
        self._address = address

    @property
    def bit_generator(self):
        """The Generator's bit generator (its seed sequence, its state)."""
        return self.generator.bit_generator

    # plain-Python use (set-up code): the Generator itself, on the same state
    def standard_normal(self, size: int | None = None):
        return self.generator.standard_normal(size)

    def random(self, size: int | None = None):
        return self.generator.random(size)

    def uniform(self, low: float = 0.0, high: float = 1.0, size: int | None = None):
        return self.generator.uniform(low, high, size)

    def normal(self, loc: float = 0.0, scale: float = 1.0, size: int | None = None):
        return self.generator.normal(loc, scale, size)


class Pcg64StreamType(types.Type):
    def __init__(self):
        super().__init__(name="Pcg64Stream")


pcg64_stream_type = Pcg64StreamType()


@typeof_impl.register(Pcg64Stream)
def _typeof_pcg64_stream(val, c):
    return pcg64_stream_type


@register_model(Pcg64StreamType)
class _Pcg64StreamModel(models.StructModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, [("state", _STATE_POINTER)])


_register_draws(Pcg64StreamType, pcg64_standard_normal, pcg64_double)


def resampling_draws(rng, systematic, m):
    """How many uniforms a resampling step draws: M with a numpy Generator (today's stream,
    whatever the scheme), 1 with a FastRng when the scheme is systematic (it reads only one)."""
    return m


@overload(resampling_draws)
def _ol_resampling_draws(rng, systematic, m):
    if isinstance(rng, FastRngType):
        return lambda rng, systematic, m: 1 if systematic else m
    return lambda rng, systematic, m: m


def loop_rng(rng: np.random.Generator, random_numbers: str):
    """The generator a jitted loop is given: for ``numpy``, ``rng``'s own stream (a
    :class:`Pcg64Stream` on it, or ``rng`` itself if it is not on PCG64); for ``fast`` a
    :class:`FastRng` seeded from ``rng``'s SeedSequence (its own stream)."""
    if random_numbers == "numpy":
        return Pcg64Stream(rng) if _pcg64_words_address(rng) is not None else rng
    if random_numbers == "fast":
        return FastRng.from_seed(rng.bit_generator.seed_seq)
    raise ValueError(f"unknown random_numbers {random_numbers!r}")


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


def normal_numpy(state, n: int) -> np.ndarray:
    """Reference ziggurat normals from :func:`xoshiro_numpy` words (same tables, same bit use)."""
    state = np.asarray(state, dtype=np.uint64).copy()

    def word():
        nonlocal state
        w, state = xoshiro_numpy(state, 1)
        return int(w[0])

    def uni():
        return (word() >> 11) * 2.0**-53

    out = np.empty(n)
    for j in range(n):
        while True:
            u = word()
            i, negative, rabs = u & 0xFF, (u >> 8) & 1, u >> 12
            x = rabs * float(ZIG_WI[i])
            if rabs < int(ZIG_KI[i]):
                break
            if i == 0:
                while True:
                    xx = -math.log1p(-uni()) / ZIG_R
                    yy = -math.log1p(-uni())
                    if yy + yy > xx * xx:
                        break
                x = ZIG_R + xx
                break
            if ZIG_FI[i] + uni() * (ZIG_FI[i + 1] - ZIG_FI[i]) < math.exp(-0.5 * x * x):
                break
        out[j] = -x if negative else x
    return out
