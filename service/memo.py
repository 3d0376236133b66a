"""Results computed from a frame's arrays, kept for the next pipeline run on the same arrays.

The web viewer runs the pipeline again on one kept copy of a frame at every slider move; what
only depends on that copy's arrays and on parameters the slider did not change (the curvature,
the lights' smoothing) need not be computed again. A :class:`Memo` given to a run
(:attr:`service.operators.base.Context.memo`) keeps those results between runs; the default,
``Memo(0)`` (``depict enhance``, the HTTP service, ``batch``), keeps nothing.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterable, Sequence
from types import ModuleType
from typing import Any, TypeVar

import numpy as np

__all__ = ["Memo", "held_bytes"]

T = TypeVar("T")


class Memo:
    """At most ``size`` results (0: none), the least recently used dropped first, each keyed by
    a name, the identities of the arrays it was computed from and the parameters it depends on.

    An entry holds its arrays, so that their identities are not reused while it lives. The
    caller vouches that nothing writes into those arrays (the viewer's copy: no operator
    writes into the frame it is given, ``tests/test_viewer_work.py``) nor into a result.

    ``stable``: the arrays that outlive the memo (the viewer's copy of a frame). Given, only
    results computed from those alone are kept: one computed from arrays an earlier step of the
    run made (new at every run, Light Alignment's lights before Radiance Scaling) would never be
    asked for again, and would hold those arrays.
    """

    def __init__(self, size: int = 4, stable: Iterable[np.ndarray] | None = None) -> None:
        self.size = size
        self._kept: OrderedDict[Hashable, tuple[tuple[np.ndarray | None, ...], Any]] = OrderedDict()
        self._stable = None if stable is None else {id(a): a for a in stable}

    def get(
        self,
        name: str,
        arrays: Sequence[np.ndarray | None],
        params: tuple[Hashable, ...],
        compute: Callable[[], T],
    ) -> T:
        """The result of ``compute()`` for these ``arrays`` and ``params``: kept, or computed
        now and kept (where it may be: ``size``, ``stable``)."""
        key = (name, tuple(id(a) for a in arrays), params)
        hit = self._kept.get(key)
        if hit is not None:  # (its arrays are these: the entry holds them, their ids are theirs)
            self._kept.move_to_end(key)
            result: T = hit[1]
            return result
        value = compute()
        if self._stable is not None and any(
            a is not None and id(a) not in self._stable for a in arrays
        ):
            return value
        self._kept[key] = (tuple(arrays), value)
        while len(self._kept) > self.size:
            self._kept.popitem(last=False)
        return value

    @property
    def nbytes(self) -> int:
        """The bytes the kept entries hold now, results and the arrays they were computed from
        (:func:`held_bytes`), but for the ``stable`` arrays."""
        besides = [] if self._stable is None else list(self._stable.values())
        return held_bytes(list(self._kept.values()), besides)

    def trim(self, nbytes: int) -> None:
        """Let go of the least recently used results until those kept hold at most ``nbytes``."""
        while self._kept and self.nbytes > nbytes:
            self._kept.popitem(last=False)


def held_bytes(value: Any, besides: Sequence[np.ndarray] = ()) -> int:
    """The bytes of the arrays ``value`` holds, in its containers and its objects' attributes
    (their ``__dict__``: a lazily computed result's cache included; not modules, functions or
    classes), each buffer once (a view counts its base array), leaving out the buffers of
    ``besides``."""
    counted = {id(_base(a)) for a in besides}
    seen: set[int] = set()
    total, todo = 0, [value]
    while todo:
        item = todo.pop()
        if isinstance(item, np.ndarray):
            base = _base(item)
            if id(base) not in counted:
                counted.add(id(base))
                total += base.nbytes
        elif id(item) in seen or callable(item) or isinstance(item, ModuleType):
            continue
        elif isinstance(item, (list, tuple, set, frozenset)):
            seen.add(id(item))
            todo.extend(item)
        elif isinstance(item, dict):
            seen.add(id(item))
            todo.extend(item.values())
        else:
            seen.add(id(item))
            attributes = getattr(item, "__dict__", None)
            if isinstance(attributes, dict):
                todo.extend(attributes.values())
    return total


def _base(array: np.ndarray) -> np.ndarray:
    """The array that owns ``array``'s buffer (itself, or the base of a view)."""
    while isinstance(array.base, np.ndarray):
        array = array.base
    return array
