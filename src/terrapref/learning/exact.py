"""Arithmetic whose result bits do not depend on the CPU, the BLAS library or the thread count.

Training a network is chaotic: a difference in the last bit of one product grows, step after
step, into different weights (PyTorch's AVX2 and AVX-512 kernels gave weights 3.16 apart after
300 epochs of C, and a different zone success). The cause is that the order in which a matrix
product adds its terms, and whether it fuses a multiply with the add, depends on the kernel
the library picks for the CPU. Three tools remove that dependence:

- :func:`matmul`: a float64 matrix product that is *exact*. Each operand is rounded to a
  fixed-point grid: ``bits`` significant bits relative to its largest entry (a block
  floating-point format). Every product of two such numbers, and every partial sum of up to
  ``2 ** (53 - 2 * bits)`` of them, is then an integer multiple of one power of two that fits
  in float64's 53-bit significand, so every summation order, with or without fused
  multiply-add, gives the same exact result. Longer sums are cut into chunks that are added in
  a fixed order.
- :func:`exp` and :func:`log`: built from +, -, *, / and exact scalings by powers of two, which
  IEEE 754 rounds the same way everywhere (NumPy's own ``exp`` and ``log`` pick SIMD versions
  per CPU whose last bits differ).
- :func:`fsum`: a correctly rounded sum (``math.fsum``), independent of order.

Elementwise +, -, *, /, sqrt, comparisons and ``rint`` are correctly rounded by IEEE 754 and need
nothing more; NumPy never fuses two ufunc calls into one multiply-add.

The elementwise chains (exp's and log's polynomials, a row's sum, an operand's rounding) run as
compiled loops (Numba, without fast-math, so nothing is reassociated or fused): each element
goes through exactly the operations, in exactly the order, that the NumPy form written in their
comments would apply, in one pass instead of a dozen (tests/learning/test_exact.py compares the two).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

MAX_EXACT = 1 << 17  # longest sum done in one exact product (18 bits per operand)

_LN2_HI = 0.693145751953125  # ln 2 split so that k * _LN2_HI is exact for |k| < 2 ** 11
_LN2_LO = 1.4286068203094173e-06
_INV_LN2 = 1.4426950408889634
# Taylor coefficients 1/j! for exp on |r| <= ln(2) / 2 (truncation error below 1e-17).
_EXP_COEF = tuple(1.0 / math.factorial(j) for j in range(14))
_SQRT_HALF = 0.7071067811865476


class Rounded(NamedTuple):
    """An operand already on its fixed-point grid: ``ints * unit`` (``ints`` float64 integers of at
    most ``bits`` bits). Round a constant operand once (:func:`rounded`) rather than per product."""

    ints: np.ndarray
    unit: float
    bits: int


def rounded(x: np.ndarray, bits: int) -> Rounded:
    """``x`` rounded to ``bits`` significant bits relative to its largest magnitude."""
    x = np.asarray(x, dtype=np.float64)
    if not x.size:
        return Rounded(x.copy(), math.ldexp(1.0, -bits), bits)
    flat = np.ascontiguousarray(x).reshape(-1)
    ints = np.empty_like(flat)
    # Per element rint(x * 2 ** (bits - e)), e the exponent of the largest magnitude: powers of
    # two, so the scaling is exact (one compiled pass for the largest entry, one for the integers).
    unit = round_into(flat, bits, ints)
    return Rounded(ints.reshape(x.shape), unit, bits)


def sum_bits(k: int) -> int:
    """Bits a sum of ``k`` terms can add to its terms'."""
    return max(0, k - 1).bit_length()


def matmul(a: np.ndarray | Rounded, b: np.ndarray | Rounded) -> np.ndarray:
    """``a @ b`` for (n, K) and (K, p), exact after rounding the operands (see above); float64 (n, p).

    An operand given as an array is rounded to a fixed-point grid relative to its largest entry:
    (53 - log2 K) / 2 significant bits (22 for K <= 512, 19 for K <= 32768), or what the other,
    :class:`Rounded`, operand leaves of float64's 53 (at most 26). The products are then summed
    exactly, so the result does not depend on how the library orders the sum. Sums longer than
    2 ** 17 terms are cut into chunks added in a fixed order.
    """
    a_ints = a.ints if isinstance(a, Rounded) else np.asarray(a, dtype=np.float64)
    b_ints = b.ints if isinstance(b, Rounded) else np.asarray(b, dtype=np.float64)
    if a_ints.ndim != 2 or b_ints.ndim != 2 or a_ints.shape[1] != b_ints.shape[0]:
        raise ValueError(f"matmul needs (n, K) and (K, p), got {a_ints.shape} and {b_ints.shape}")
    k = a_ints.shape[1]
    if k == 0:
        return np.zeros((a_ints.shape[0], b_ints.shape[1]))
    if k > MAX_EXACT:
        out = None
        for start in range(0, k, MAX_EXACT):  # exact chunks, added in this fixed order
            part = matmul(_columns(a, start), _rows(b, start))
            out = part if out is None else out + part
        return out
    room = 53 - sum_bits(k)
    if not isinstance(a, Rounded):
        a = rounded(a_ints, min(26, room - b.bits) if isinstance(b, Rounded) else room // 2)
    if not isinstance(b, Rounded):
        b = rounded(b_ints, min(26, room - a.bits))
    if a.bits + b.bits > room:
        raise ValueError(f"operands of {a.bits} and {b.bits} bits cannot be summed exactly over {k} terms")
    return (a.ints @ b.ints) * (a.unit * b.unit)


def _columns(a: np.ndarray | Rounded, start: int) -> np.ndarray | Rounded:
    cut = slice(start, start + MAX_EXACT)
    return a._replace(ints=a.ints[:, cut]) if isinstance(a, Rounded) else a[:, cut]


def _rows(b: np.ndarray | Rounded, start: int) -> np.ndarray | Rounded:
    cut = slice(start, start + MAX_EXACT)
    return b._replace(ints=b.ints[cut]) if isinstance(b, Rounded) else b[cut]


def exp(x: np.ndarray) -> np.ndarray:
    """e ** x, float64, the same bits on every CPU (relative error below 1e-15).

    Range reduction x = k ln 2 + r with |r| <= ln(2) / 2, a degree-13 Taylor polynomial for
    e ** r, and an exact scaling by 2 ** k.
    """
    x = np.asarray(x, dtype=np.float64)
    return exp_flat(np.ascontiguousarray(x).reshape(-1)).reshape(x.shape)


_EXP_HORNER = tuple(_EXP_COEF[-2::-1])  # a constant tuple, so the compiled polynomial is unrolled
# 2 ** e for every e a scaling can need (k in [-1068, 1023]), each exact (the smallest are
# subnormal powers of two): p * 2 ** k is one correctly rounded product, ldexp(p, k)'s bits.
_POW2 = np.array([math.ldexp(1.0, e) for e in range(-1074, 1024)])


@njit(cache=True, nogil=True, inline="always")
def exp1(v: float) -> float:
    """One element of :func:`exp` (for compiled loops that take their exponentials one at a time)."""
    v = -740.0 if v < -740.0 else v  # NaN passes through both
    v = 709.0 if v > 709.0 else v
    k = np.rint(v * _INV_LN2)
    r = (v - k * _LN2_HI) - k * _LN2_LO
    q = _EXP_COEF[-1]
    for c in _EXP_HORNER:
        q = q * r + c
    return q * _POW2[np.int64(k) + 1074] if k == k else q  # NaN stays NaN


@njit(cache=True, nogil=True)
def exp_flat(x: np.ndarray) -> np.ndarray:
    """:func:`exp` of a flat array (for compiled callers). Per element, the NumPy form:
    ``x = clip(x, -740, 709); k = rint(x / ln 2); r = (x - k ln2_hi) - k ln2_lo;
    p = coef[-1]; p = p * r + c for c in coef[-2::-1]; ldexp(p, k)``,
    the scaling as a product with the exact power of two from a table (a library ldexp call
    per element cost as much as the rest)."""
    n = x.shape[0]
    p = np.empty(n)
    for i in range(n):
        p[i] = exp1(x[i])
    return p


def log(x: np.ndarray) -> np.ndarray:
    """Natural logarithm of positive float64 values, the same bits on every CPU.

    x = f 2 ** e with f in [sqrt(1/2), sqrt(2)); ln f = 2 atanh(s), s = (f - 1) / (f + 1), from
    its series (|s| < 0.172, 11 terms). Non-positive input gives -inf (0) or nan (< 0).
    """
    x = np.asarray(x, dtype=np.float64)
    return log_flat(np.ascontiguousarray(x).reshape(-1)).reshape(x.shape)


@njit(cache=True, nogil=True)
def log_flat(x: np.ndarray) -> np.ndarray:
    """:func:`log` of a flat array (for compiled callers). Per element, the NumPy form: ``f, e = frexp(x); f, e = (2 f, e - 1) if f < sqrt(1/2);
    s = (f - 1) / (f + 1); series = 1/21; series = series * s**2 + 1/j for j = 19, 17, ..., 1;
    2 s series + e ln2_lo + e ln2_hi``."""
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        v = x[i]
        if not v > 0:
            out[i] = -np.inf if v == 0 else np.nan
            continue
        f, e = math.frexp(v)
        if f < _SQRT_HALF:
            f = f * 2.0
            e = e - 1
        s = (f - 1.0) / (f + 1.0)
        s2 = s * s
        series = 1.0 / 21.0
        for j in range(19, 0, -2):
            series = series * s2 + 1.0 / j
        ef = np.float64(e)
        out[i] = 2.0 * s * series + ef * _LN2_LO + ef * _LN2_HI
    return out


def row_sum(x: np.ndarray) -> np.ndarray:
    """Sum over the last axis, added left to right: the same order, so the same bits, everywhere."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 0 or x.shape[-1] == 0:
        raise ValueError(f"row_sum needs at least one column, got shape {x.shape}")
    rows = np.ascontiguousarray(x).reshape(-1, x.shape[-1])
    return _row_sum(rows).reshape(x.shape[:-1])


@njit(cache=True, nogil=True)
def _row_sum(x: np.ndarray) -> np.ndarray:
    out = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        total = x[i, 0]
        for j in range(1, x.shape[1]):
            total = total + x[i, j]
        out[i] = total
    return out


def fsum(values: np.ndarray) -> float:
    """The correctly rounded sum of ``values``: one answer whatever the order or the CPU."""
    return math.fsum(np.asarray(values, dtype=np.float64).ravel().tolist())


# --- the exact product inside compiled loops -------------------------------------------------------
# The same grids, bit counts and chunks as :func:`matmul`, for loops that run a whole fit in
# compiled code. Each sum of exact products is exact, so the loops may add in any order and still
# give :func:`matmul`'s bits.


_ABS_BITS = np.int64(0x7FFFFFFFFFFFFFFF)  # a float64's bits without its sign
_INF_BITS = np.int64(0x7FF0000000000000)  # +inf's; any larger magnitude's bits are a NaN's


@njit(cache=True, nogil=True)
def largest_magnitude(x: np.ndarray) -> float:
    """``max(x.max(), -x.min())`` of a flat array, NaN if any entry is NaN (as :func:`rounded`).

    Non-negative floats order as their bit patterns do, and a NaN's magnitude bits exceed
    infinity's, so the largest magnitude is an integer maximum (which the compiler vectorises;
    a float maximum with NaN checks it does not). Only its exponent is used."""
    bits = x.view(np.int64)
    top = np.int64(0)
    for i in range(bits.shape[0]):
        b = bits[i] & _ABS_BITS
        top = b if b > top else top
    if top > _INF_BITS:
        return np.nan
    return np.array([top]).view(np.float64)[0]


@njit(cache=True, nogil=True)
def round_into(x: np.ndarray, bits: int, out: np.ndarray) -> float:
    """:func:`rounded` of a flat array into ``out`` (the integers); returns the grid's unit."""
    e = math.frexp(largest_magnitude(x))[1] if x.shape[0] else 0
    scale = math.ldexp(1.0, bits - e)
    for i in range(x.shape[0]):
        out[i] = np.rint(x[i] * scale)
    return math.ldexp(1.0, e - bits)


@njit(cache=True, nogil=True)
def chunk_bits(k: int) -> int:
    """Bits left to the operands of an exact sum of ``k`` products (``53 - sum_bits(k)``)."""
    bits, top = 0, k - 1
    while top > 0:
        bits += 1
        top >>= 1
    return 53 - bits


@njit(cache=True, nogil=True)
def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """Sum of ``a[i] * b[i]`` over two equal-length arrays of integers whose every partial sum is
    exact: eight running sums (independent chains the CPU overlaps), then added; exact, so the
    grouping does not change the result."""
    n = a.shape[0]
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
    top = n - n % 8
    for i in range(0, top, 8):
        s0 += a[i] * b[i]
        s1 += a[i + 1] * b[i + 1]
        s2 += a[i + 2] * b[i + 2]
        s3 += a[i + 3] * b[i + 3]
        s4 += a[i + 4] * b[i + 4]
        s5 += a[i + 5] * b[i + 5]
        s6 += a[i + 6] * b[i + 6]
        s7 += a[i + 7] * b[i + 7]
    for i in range(top, n):
        s0 += a[i] * b[i]
    return ((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7))


@njit(cache=True, nogil=True)
def vec_mat_rounded(a: np.ndarray, b_columns: np.ndarray, b_unit: float, b_bits: int, out: np.ndarray) -> None:
    """``matmul(a[None], Rounded(b_columns.T, b_unit, b_bits))[0]`` into ``out`` (p,), with the
    rounded operand's integers given by columns, (p, K): ``a`` (K,) is rounded chunk by chunk to
    what ``b`` leaves, each chunk's sum is exact, and chunks are added in order."""
    p, k = b_columns.shape
    ints = np.empty(min(k, MAX_EXACT))
    for start in range(0, k, MAX_EXACT):
        stop = min(k, start + MAX_EXACT)
        bits = min(26, chunk_bits(stop - start) - b_bits)
        unit = round_into(a[start:stop], bits, ints) * b_unit
        for j in range(p):
            part = _dot(ints[: stop - start], b_columns[j, start:stop]) * unit
            out[j] = part if start == 0 else out[j] + part


@njit(cache=True, nogil=True)
def vec_mat(a: np.ndarray, b: np.ndarray, p: int, out: np.ndarray) -> None:
    """``matmul(a[None], b.reshape(K, p))[0]`` into ``out`` (p,) for two plain operands, ``a`` (K,)
    and ``b`` (K * p,) row-major: per chunk, ``a`` to half the room and ``b`` (relative to the
    chunk's largest entry) to what is left."""
    k = a.shape[0]
    a_ints = np.empty(min(k, MAX_EXACT))
    b_ints = np.empty(min(k, MAX_EXACT) * p)
    acc = np.empty(p)
    for start in range(0, k, MAX_EXACT):
        stop = min(k, start + MAX_EXACT)
        room = chunk_bits(stop - start)
        a_bits = room // 2
        a_unit = round_into(a[start:stop], a_bits, a_ints)
        b_unit = round_into(b[start * p : stop * p], min(26, room - a_bits), b_ints)
        unit = a_unit * b_unit
        acc[:] = 0.0
        for i in range(stop - start):
            ai = a_ints[i]
            for j in range(p):
                acc[j] += ai * b_ints[i * p + j]
        for j in range(p):
            out[j] = acc[j] * unit if start == 0 else out[j] + acc[j] * unit
