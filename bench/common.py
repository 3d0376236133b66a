"""Benchmark harness: medians and the ratio to a memory-bound copy measured in the same run.

Every benchmark prints ``name  median_ms  ratio`` where ratio = median / copy unit, the copy unit
being the median time to copy an H×W×3 float32 array of the same size from memory to memory.
Ratios are what the issues' targets are written in; absolute times vary from machine to machine.

Memory to memory: a 1080p frame (23.7 MiB) and its copy (47 MiB together) fit in large part in a
32 MiB last-level cache, so the same array copied again and again runs partly from the cache, by
as much as the machine's other tenants leave it (1.2-2.5 ms on a 2-core machine whose copies of
arrays many times its cache take 2.2-3.1 ms per frame). The unit therefore copies a different
frame each time, from a ring of frames holding several times the last-level cache, as an
operator's own arrays (tens of frames) are read from memory; the same copy in cache is printed
beside it.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from pathlib import Path

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


#: The ring of frames the copy unit cycles through holds at least this many last-level caches.
_RING_CACHES = 4


def last_level_cache_bytes(default: int = 64 << 20) -> int:
    """The largest CPU cache's size in bytes (Linux sysfs), ``default`` where it cannot be read."""
    sizes = [
        cache_size(path.read_text())
        for path in Path("/sys/devices/system/cpu/cpu0/cache").glob("index*/size")
    ]
    return max((size for size in sizes if size), default=default)


def cache_size(text: str) -> int:
    """A sysfs cache size ("32768K", "2M", "512") in bytes; 0 for anything else."""
    text = text.strip().upper()
    scale = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}.get(text[-1:], 1)
    digits = text[:-1] if scale > 1 else text
    return int(digits) * scale if digits.isdigit() else 0


class _Copy:
    """(H, W, 3) float32 frames and their destinations, each copied in turn (one per timed copy),
    so many that a frame has left the last-level cache when its turn comes again."""

    def __init__(self, shape: tuple[int, int], cache_bytes: int | None = None) -> None:
        frame = np.random.default_rng(0).random((*shape, 3), dtype=np.float32)
        cache = last_level_cache_bytes() if cache_bytes is None else cache_bytes
        pairs = max(2, -(-_RING_CACHES * cache // (2 * frame.nbytes)))
        self.ring = [(frame.copy(), frame.copy()) for _ in range(pairs)]  # (pages touched)
        self.src, self.dst = frame, frame.copy()  # (the copy in cache, for comparison)
        self._next = 0

    def _copy_next(self) -> None:
        src, dst = self.ring[self._next]
        self._next = (self._next + 1) % len(self.ring)
        np.copyto(dst, src)

    def median_ms(self, repeat: int, warmup: int = 3) -> float:
        """The unit: the median time of ``repeat`` copies from memory to memory."""
        return median_ms(self._copy_next, repeat=repeat, warmup=warmup)

    def cached_ms(self, repeat: int = 21) -> float:
        """The median time to copy one frame to the same destination again and again (partly
        from the cache: what this unit was before, printed beside it)."""
        return median_ms(lambda: np.copyto(self.dst, self.src), repeat=repeat, warmup=3)


class Report:
    """Collects timings and prints them with their ratio to the copy unit."""

    def __init__(self, title: str, shape: tuple[int, int] = HD) -> None:
        self.title = title
        self.copy = _Copy(shape)
        self.unit = self.copy.median_ms(21)
        self.rows: list[tuple[str, float, float | None]] = []
        print(
            f"== {title} ({shape[1]}x{shape[0]}); copy unit {self.unit:.2f} ms "
            f"(memory to memory; the same copy in cache {self.copy.cached_ms():.2f} ms)"
        )

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
