"""NumPy's summation order, compiled: for loops that must give the bits of a NumPy ``sum``.

Shared by the features (terrapref.features.utility_compiled, terrapref.rules.second.scores_compiled) and the synthetic driver
(terrapref.demos.expert), which keeps apart from the feature pipeline (SPEC 10).

Compiled into its callers, whose cached copies Numba does not recompile when only this file
changes: after editing it, delete the ``__pycache__`` folders' ``*.nbi``/``*.nbc`` files
(``python -m terrapref.warm_up`` rebuilds them).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def numpy_sum(a: np.ndarray) -> float:
    """``a.sum()`` of a 1-D float64 array as NumPy adds it: from 0, in eight interleaved partial
    sums added pairwise, then the last ``n % 8`` terms in order (its pairwise summation for
    n <= 128; longer arrays are not summed here)."""
    n = a.shape[0]
    if n > 128:
        raise ValueError("numpy_sum follows NumPy's summation order for at most 128 terms")
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[i]
        return 0.0 + res
    r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    i = 8
    while i < n - n % 8:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[i]
        i += 1
    return 0.0 + res
