"""numpy's own random streams drawn from jitted code: the same numbers, several times faster.

A numpy Generator inside numba costs an indirect call into the bit generator per 64-bit
word, and numpy's own array draws (``Generator.standard_normal(size)``) cost about 12 ns a
normal on the 2-core machine (docs/speed.md). For a Generator on PCG64 (numpy's default),
:class:`Pcg64Stream` steps the very same PCG64 state in place from jitted code (128-bit LCG,
XSL-RR output, as numpy's pcg64.h) and applies the same transformations numba's Generator
methods apply (numpy's 256-layer ziggurat and tables, uniforms as 53-bit words): the same
numbers in the same order, the Generator's state advanced exactly as if it had drawn them
itself (about 2.7 ns a normal).

Two users: the filters' ``filter.random_numbers: numpy`` (``filters/rng.py`` fills their
noise blocks through :func:`pcg64_fill`), and the simulation of a run's sensors
(:func:`standard_normal`, :func:`uniform`: what ``generator.standard_normal(shape)`` and
``generator.uniform(low, high, shape)`` return, bit for bit). A base-layer module, so that
the sensors draw from it without importing the filters.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import (NativeValue, intrinsic, make_attribute_wrapper, models, register_model, typeof_impl,
                             unbox)
from numba.np.random._constants import fi_double, ki_double, wi_double, ziggurat_nor_inv_r, ziggurat_nor_r

from tanbench.fastmath import FASTMATH

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
    # the sign by a multiplication, not a branch (a mispredicted branch on every other draw cost
    # more than the rest of the draw); x * -1.0 is exactly -x
    x = np.float64(rabs) * wi_double[idx] * (1.0 - 2.0 * np.float64(r & np.uint64(1)))
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


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def pcg64_fill(w, out, normal, low, high):
    """numpy's standard normals (or uniforms in [low, high)) from the PCG64 words ``w``, in order."""
    scale = high - low
    for j in range(out.shape[0]):
        out[j] = pcg64_standard_normal(w) if normal else low + scale * pcg64_double(w)


def pcg64_words_address(generator: np.random.Generator) -> int | None:
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
    """A numpy Generator on PCG64, as the jitted fills draw from it: exactly the numbers the
    Generator's ``standard_normal()`` and ``uniform(low, high)`` would give, in order, its state
    advanced as if it had drawn them. Holds the Generator (whose memory it uses)."""

    def __init__(self, generator: np.random.Generator, address: int | None = None):
        """``address``: the Generator's :func:`pcg64_words_address`, when the caller has already found it."""
        address = pcg64_words_address(generator) if address is None else address
        if address is None:
            raise ValueError("Pcg64Stream needs a numpy Generator on PCG64")
        self.generator = generator
        self._address = address

    @property
    def bit_generator(self):
        """The Generator's bit generator (its seed sequence, its state)."""
        return self.generator.bit_generator


class Pcg64StreamType(types.Type):
    def __init__(self):
        super().__init__(name="Pcg64Stream")


pcg64_stream_type = Pcg64StreamType()
_STATE_POINTER = types.CPointer(types.uint64)


@typeof_impl.register(Pcg64Stream)
def _typeof_pcg64_stream(val, c):
    return pcg64_stream_type


@register_model(Pcg64StreamType)
class _Pcg64StreamModel(models.StructModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, [("state", _STATE_POINTER)])


make_attribute_wrapper(Pcg64StreamType, "state", "state")


@unbox(Pcg64StreamType)
def _unbox_pcg64_stream(typ, obj, c):
    """A stream's native form is a pointer to the Generator's PCG64 words (``obj._address``),
    borrowed for the call (the Generator keeps the memory alive; draws advance it)."""
    addr_obj = c.pyapi.object_getattr_string(obj, "_address")
    addr = c.pyapi.long_as_voidptr(addr_obj)
    c.pyapi.decref(addr_obj)
    stream = cgutils.create_struct_proxy(typ)(c.context, c.builder)
    stream.state = c.builder.bitcast(addr, c.context.get_value_type(_STATE_POINTER))
    return NativeValue(stream._getvalue(), is_error=cgutils.is_not_null(c.builder, c.pyapi.err_occurred()))


@nb.njit(cache=True)
def _stream_fill(stream, out, normal, low, high):
    """:func:`pcg64_fill` from a :class:`Pcg64Stream` (``out`` 1-D)."""
    pcg64_fill(stream.state, out, normal, low, high)


def pcg64_stream(generator: np.random.Generator) -> Pcg64Stream | None:
    """A :class:`Pcg64Stream` on ``generator``, or None if it is not on PCG64 (its layout checked once)."""
    address = pcg64_words_address(generator)
    return None if address is None else Pcg64Stream(generator, address)


def _draw(stream: Pcg64Stream, shape, normal: bool, low: float, high: float) -> np.ndarray:
    out = np.empty(shape)
    _stream_fill(stream, out.reshape(-1), normal, float(low), float(high))
    return out


def standard_normal(generator: np.random.Generator, shape) -> np.ndarray:
    """``generator.standard_normal(shape)`` (float64, C order): the same numbers and the same state after,
    drawn inline when the Generator is on PCG64 (by the Generator itself otherwise)."""
    stream = pcg64_stream(generator)
    return generator.standard_normal(shape) if stream is None else _draw(stream, shape, True, 0.0, 1.0)


def uniform(generator: np.random.Generator, low: float, high: float, shape) -> np.ndarray:
    """``generator.uniform(low, high, shape)`` (float64, C order), as :func:`standard_normal` draws it."""
    stream = pcg64_stream(generator)
    return generator.uniform(low, high, shape) if stream is None else _draw(stream, shape, False, low, high)
