"""What a :class:`service.memo.Memo` keeps, and the bytes it counts for it."""

from __future__ import annotations

import numpy as np

from ops.curvature import principal_curvatures
from service.memo import Memo, held_bytes


def test_the_bytes_held_count_each_buffer_once_and_not_the_inputs() -> None:
    """A view counts its base array, an array reached twice counts once, an object's attributes
    and containers are searched; the arrays a result was computed from are the caller's."""
    base = np.zeros((100, 100), np.float32)  # 40 000 bytes
    other = np.ones(1000, np.float64)  # 8 000 bytes
    value = {"a": [base[:10], base, (other, other[::2])], "b": None}
    assert held_bytes(value) == 48_000
    assert held_bytes(value, besides=[base[5:]]) == 8_000


def test_a_memo_counts_what_it_keeps_and_trims_the_least_recently_used() -> None:
    """Two results kept, each of its own arrays (a lazily upsampled curvature: its working
    grid); trimmed to fewer bytes, the one used least recently goes first, and a result whose
    arrays are its inputs costs nothing."""
    memo = Memo()
    normal = np.zeros((64, 64, 3), np.float32)
    normal[..., 2] = 1.0
    depth = np.full((64, 64), 2.0, np.float32)
    mask = np.ones((64, 64), np.float32)

    def curvature(scale: float) -> object:
        return memo.get(
            "curvature",
            (normal, depth, mask),
            (scale,),
            lambda: principal_curvatures(normal, depth, mask, scale=scale),
        )

    first = curvature(0.01)
    second = curvature(0.05)
    one = held_bytes(first)
    assert one > 0 and memo.nbytes == one + held_bytes(second)
    memo.get("same", (depth,), (), lambda: depth)
    assert memo.nbytes == one + held_bytes(second)
    assert curvature(0.01) is first  # (used last: the second is the least recently used)
    memo.trim(memo.nbytes - 1)
    assert memo.nbytes == one
    assert curvature(0.01) is first and curvature(0.05) is not second
    memo.trim(0)
    assert memo.nbytes == 0 and curvature(0.01) is not first
