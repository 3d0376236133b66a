"""service.allocator: the glibc settings are applied once per process, and can be turned off."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

CODE = "from service import allocator; print(allocator.tune(), allocator.tune())"


def _run(env: dict[str, str]) -> str:
    out = subprocess.run(
        [sys.executable, "-c", CODE],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout.strip()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_tune_applies_on_glibc() -> None:
    assert _run({"DEPICT_MALLOC": "tuned"}) == "True True"


def test_system_leaves_the_allocator() -> None:
    assert _run({"DEPICT_MALLOC": "system"}) == "False False"


HUGE = """
import os, sys
if sys.argv[1] == "before":
    import numpy
from service import allocator
allocator.tune()
import numpy
print(os.environ.get("NUMPY_MADVISE_HUGEPAGE"), numpy._core.multiarray._set_madvise_hugepage(0))
"""


@pytest.mark.parametrize("numpy_imported", ["before", "after"])
def test_numpy_gives_no_huge_page_advice_unless_the_user_asks(numpy_imported: str) -> None:
    """``tune`` turns NumPy's huge-page advice off (the setter returns the setting it replaces),
    whether NumPy was imported before it or after; a user's own setting wins."""
    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    for given, expected in ((None, ["0", "False"]), ("1", ["1", "True"])):
        if given is not None:
            env["NUMPY_MADVISE_HUGEPAGE"] = given
        cmd = [sys.executable, "-c", HUGE, numpy_imported]
        run = subprocess.run(cmd, env=env, capture_output=True, text=True)
        assert run.stdout.split() == expected, run.stderr


KEPT = """
import sys, threading
import numpy as np
from service import allocator
print(allocator.tune())

def rss_mib():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20

def touch_and_free(n=20):  # 20 arrays of 8 MiB (below the mmap threshold: from a heap)
    arrays = [np.ones(2 << 20, np.float32) for _ in range(n)]
    del arrays

base = rss_mib()
worker = threading.Thread(target=touch_and_free)
worker.start()
worker.join()
after_thread = rss_mib()
touch_and_free()
after_main = rss_mib()
allocator.release_free()
print(round(after_thread - base), round(after_main - base), round(rss_mib() - base))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_freed_memory_is_kept_once_for_every_thread_and_given_back_on_request() -> None:
    """Tuned, 160 MiB freed by a worker thread stay in the process (no page faults to reuse
    them) and the main thread's next 160 MiB reuse them (one arena for every thread: with
    glibc's arena per thread the process held 272 MiB); ``release_free`` gives them back."""
    run = subprocess.run([sys.executable, "-c", KEPT], capture_output=True, text=True)
    lines = run.stdout.split("\n")
    assert lines[0] == "True", run.stderr
    after_thread, after_main, released = (int(x) for x in lines[1].split())
    assert after_thread >= 150
    assert after_main < after_thread + 40
    assert released < 40
