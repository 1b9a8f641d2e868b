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
from numba.core import cgutils, types
from numba.extending import (NativeValue, make_attribute_wrapper, models, overload, overload_method,
                             register_model, typeof_impl, unbox)

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


make_attribute_wrapper(FastRngType, "state", "state")


@unbox(FastRngType)
def _unbox_fast_rng(typ, obj, c):
    """A FastRng's native form is a pointer to its state array's words, borrowed for the call
    (the Python object keeps the array alive; draws advance it). A pointer, not an array,
    so a draw costs no reference counting."""
    addr_obj = c.pyapi.object_getattr_string(obj, "_address")
    addr = c.pyapi.long_as_voidptr(addr_obj)
    c.pyapi.decref(addr_obj)
    rng = cgutils.create_struct_proxy(typ)(c.context, c.builder)
    rng.state = c.builder.bitcast(addr, c.context.get_value_type(_STATE_POINTER))
    return NativeValue(rng._getvalue(), is_error=cgutils.is_not_null(c.builder, c.pyapi.err_occurred()))


@overload_method(FastRngType, "standard_normal")
def _ol_standard_normal(rng):
    def impl(rng):
        return standard_normal(rng.state)
    return impl


@overload_method(FastRngType, "random")
def _ol_random(rng):
    def impl(rng):
        return uniform01(rng.state)
    return impl


@overload_method(FastRngType, "uniform")
def _ol_uniform(rng, low=0.0, high=1.0):
    def impl(rng, low=0.0, high=1.0):
        return low + (high - low) * uniform01(rng.state)
    return impl


@overload_method(FastRngType, "normal")
def _ol_normal(rng, loc=0.0, scale=1.0):
    def impl(rng, loc=0.0, scale=1.0):
        return loc + scale * standard_normal(rng.state)
    return impl


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
    """The generator a jitted loop is given: ``rng`` itself, or for ``fast`` a
    :class:`FastRng` seeded from ``rng``'s SeedSequence (its own stream)."""
    if random_numbers == "numpy":
        return rng
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
