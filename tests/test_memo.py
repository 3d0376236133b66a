"""What a :class:`service.memo.Memo` keeps, and the bytes it counts for it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ops.curvature import principal_curvatures
from service.memo import Memo, held_bytes


def test_the_bytes_held_count_each_buffer_once_and_not_the_inputs() -> None:
    """A view counts its base array, an array reached twice counts once, containers and
    objects' attributes are searched (not modules or functions); the arrays of ``besides``
    are the caller's."""
    base = np.zeros((100, 100), np.float32)  # 40 000 bytes
    other = np.ones(1000, np.float64)  # 8 000 bytes
    holder = SimpleNamespace(field=other[::2], module=np, function=len)
    value = {"a": [base[:10], base, (other, holder)], "b": None, "c": np}
    assert held_bytes(value) == 48_000
    assert held_bytes(value, besides=[base[5:]]) == 8_000


def test_a_memo_counts_what_it_keeps_and_trims_the_least_recently_used() -> None:
    """Results of the ``stable`` arrays (the viewer's copy) are kept and counted without those
    arrays; a result of other arrays (made by an earlier step of the run) is not kept; a memo
    with no stable arrays counts the arrays it holds as keys too. Trimmed to fewer bytes, the
    least recently used goes first."""
    normal = np.zeros((64, 64, 3), np.float32)
    normal[..., 2] = 1.0
    depth = np.full((64, 64), 2.0, np.float32)
    mask = np.ones((64, 64), np.float32)
    memo = Memo(stable=[normal, depth, mask])

    def curvature(scale: float, memo: Memo = memo) -> object:
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
    made = depth + 1.0  # (an earlier step's array)
    assert memo.get("made", (made,), (), lambda: [made * 2]) is not memo.get(
        "made", (made,), (), lambda: [made * 2]
    )
    assert memo.nbytes == one + held_bytes(second)
    assert curvature(0.01) is first  # (used last: the second is the least recently used)
    memo.trim(memo.nbytes - 1)
    assert memo.nbytes == one
    assert curvature(0.01) is first and curvature(0.05) is not second
    memo.trim(0)
    assert memo.nbytes == 0 and curvature(0.01) is not first
    plain = Memo()
    kept = curvature(0.01, plain)
    assert plain.nbytes == held_bytes(kept) + normal.nbytes + depth.nbytes + mask.nbytes
