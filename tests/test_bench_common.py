"""The benchmarks' copy unit: a copy from memory to memory, not from the cache."""

from __future__ import annotations

import numpy as np

from bench.common import _Copy, cache_size, last_level_cache_bytes


def test_cache_sizes_read_as_sysfs_writes_them() -> None:
    assert cache_size("32768K\n") == 32 << 20
    assert cache_size("2M") == 2 << 20
    assert cache_size("512") == 512
    assert cache_size("") == 0
    assert cache_size("unknown") == 0
    assert last_level_cache_bytes() >= 1 << 10


def test_each_copy_of_the_unit_takes_another_frame_of_a_ring_larger_than_the_cache() -> None:
    cache = 1 << 20  # (the machine's own cache would make a ring of hundreds of MiB)
    copy = _Copy((48, 64), cache_bytes=cache)
    held = sum(src.nbytes + dst.nbytes for src, dst in copy.ring)
    assert 4 * cache <= held < 5 * cache
    for k, (src, dst) in enumerate(copy.ring[:4]):
        src.fill(k + 1.0)
        dst.fill(0.0)
    for k in range(3):
        copy.median_ms(1, warmup=0)  # one copy: the next frame of the ring
        assert np.all(copy.ring[k][1] == k + 1.0)
        assert not np.any(copy.ring[k + 1][1])
