"""Benchmark harness: medians and the ratio to a memory-bound copy measured in the same run.

Every benchmark prints ``name  median_ms  ratio`` where ratio = median / copy unit, the copy unit
being the median time to copy an H×W×3 float32 array of the same size (DESIGN.md). Ratios are what
the issues' targets are written in; absolute times vary from machine to machine.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np

from service import allocator

allocator.tune()  # as the CLI, the service and batch workers run (service/allocator.py)

HD = (1080, 1920)


def median_ms(fn: Callable[[], object], repeat: int = 7, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` in milliseconds over ``repeat`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def copy_unit_ms(shape: tuple[int, int] = HD, repeat: int = 21) -> float:
    """Median time to copy an (H, W, 3) float32 array: the memory-bound unit."""
    return _Copy(shape).median_ms(repeat)


class _Copy:
    """An (H, W, 3) float32 array and its destination, copied on demand."""

    def __init__(self, shape: tuple[int, int]) -> None:
        self.src = np.random.default_rng(0).random((*shape, 3), dtype=np.float32)
        self.dst = np.empty_like(self.src)

    def median_ms(self, repeat: int, warmup: int = 3) -> float:
        return median_ms(lambda: np.copyto(self.dst, self.src), repeat=repeat, warmup=warmup)


class Report:
    """Collects timings and prints them with their ratio to the copy unit."""

    def __init__(self, title: str, shape: tuple[int, int] = HD) -> None:
        self.title = title
        self.copy = _Copy(shape)
        self.unit = self.copy.median_ms(21)
        self.rows: list[tuple[str, float, float | None]] = []
        print(f"== {title} ({shape[1]}x{shape[0]}); copy unit {self.unit:.2f} ms")

    def add(
        self, name: str, ms: float, target_ratio: float | None = None, ratio: float | None = None
    ) -> float:
        """Print a row; its ratio is ``ms`` over the report's copy unit unless given."""
        ratio = ms / self.unit if ratio is None else ratio
        self.rows.append((name, ms, target_ratio))
        target = (
            f"  (target <= {target_ratio:g}x: {'ok' if ratio <= target_ratio else 'OVER'})"
            if target_ratio
            else ""
        )
        print(f"{name:<48s} {ms:9.1f} ms  {ratio:7.1f}x copy{target}", flush=True)
        return ratio

    def time(
        self,
        name: str,
        fn: Callable[[], object],
        repeat: int = 7,
        target_ratio: float | None = None,
    ) -> float:
        return self.add(name, median_ms(fn, repeat=repeat), target_ratio)

    def paired(
        self,
        name: str,
        fn: Callable[[], object],
        repeat: int = 9,
        target_ratio: float | None = None,
    ) -> float:
        """Like :meth:`time`, but each run of ``fn`` follows its own copy unit (the median of 5
        copies) and the ratio is the median of the runs' ratios: where the machine's speed drifts
        over the benchmark (a shared or throttled machine), each ratio sees one speed."""
        fn()
        times, ratios = [], []
        for _ in range(repeat):
            unit = self.copy.median_ms(5, warmup=1)
            times.append(median_ms(fn, repeat=1, warmup=0))
            ratios.append(times[-1] / unit)
        return self.add(name, statistics.median(times), target_ratio, statistics.median(ratios))
