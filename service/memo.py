"""Results computed from a frame's arrays, kept for the next pipeline run on the same arrays.

The web viewer runs the pipeline again on one kept copy of a frame at every slider move; what
only depends on that copy's arrays and on parameters the slider did not change (the curvature,
the lights' smoothing) need not be computed again. A :class:`Memo` given to a run
(:attr:`service.operators.base.Context.memo`) keeps those results between runs; the default,
``Memo(0)`` (``depict enhance``, the HTTP service, ``batch``), keeps nothing.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable, Sequence
from typing import Any, TypeVar

import numpy as np

__all__ = ["Memo"]

T = TypeVar("T")


class Memo:
    """At most ``size`` results (0: none), the least recently used dropped first, each keyed by
    a name, the identities of the arrays it was computed from and the parameters it depends on.

    An entry holds its arrays, so that their identities are not reused while it lives. The
    caller vouches that nothing writes into those arrays (the viewer's copy: no operator
    writes into the frame it is given, ``tests/test_viewer_work.py``) nor into a result.
    """

    def __init__(self, size: int = 4) -> None:
        self.size = size
        self._kept: OrderedDict[Hashable, tuple[tuple[np.ndarray | None, ...], Any]] = OrderedDict()

    def get(
        self,
        name: str,
        arrays: Sequence[np.ndarray | None],
        params: tuple[Hashable, ...],
        compute: Callable[[], T],
    ) -> T:
        """The result of ``compute()`` for these ``arrays`` and ``params``: kept, or computed
        now and kept."""
        key = (name, tuple(id(a) for a in arrays), params)
        hit = self._kept.get(key)
        if hit is not None:  # (its arrays are these: the entry holds them, their ids are theirs)
            self._kept.move_to_end(key)
            result: T = hit[1]
            return result
        value = compute()
        self._kept[key] = (tuple(arrays), value)
        while len(self._kept) > self.size:
            self._kept.popitem(last=False)
        return value
