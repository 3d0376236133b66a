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
