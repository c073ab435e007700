"""``np.median`` of float arrays, the same values, many times faster.

``np.median`` asks ``np.partition`` for two order statistics (three, with the one that
finds NaNs) at once, and numpy partitions for several ``kth`` with a slow generic
introselect; for a single ``kth`` it uses its vectorised selection, which on a million
float32 values is about twenty times faster. :func:`median` partitions for the upper
middle value only, takes the lower one as the maximum of the part below it, and averages
the two with ``np.mean`` exactly as ``np.median`` does, so the result has the same bits
(arrays with NaN, other dtypes and other axes are left to ``np.median``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["median"]


def median(a: np.ndarray, axis: int | None = None) -> np.ndarray | np.floating:
    """``np.median(a, axis)``: the same result, faster for float arrays (``axis`` None, or 0 of a 2-D array)."""
    x = np.asarray(a)
    if x.dtype.kind != "f" or x.size == 0 or not (axis is None or (axis == 0 and x.ndim == 2)):
        return np.median(x, axis=axis)
    if np.isnan(x.max()):  # NaN in the data: np.median's own NaN rules
        return np.median(x, axis=axis)
    if axis is None:
        return np.mean(_middle(x.ravel()))
    mids = [_middle(np.ascontiguousarray(x[:, c])) for c in range(x.shape[1])]
    return np.mean(np.stack(mids, axis=1), axis=0)  # (1 or 2, columns), as np.median averages them


def _middle(v: np.ndarray) -> np.ndarray:
    """The middle value (odd size) or the two middle values (even size) of 1-D ``v``, in order."""
    n = v.size
    h = n // 2
    p = np.partition(v, h)
    if n % 2:
        return p[h:h + 1]
    return np.array([p[:h].max(), p[h]], dtype=v.dtype)
