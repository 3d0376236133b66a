"""Golden pictures: a change of an operator's look must be deliberate (bench/golden.py).

Each default's result on committed corpus frames is compared with its picture in tests/golden/,
8-bit sRGB: the mean difference must stay under 0.5 levels of 255 and the 99.9th percentile
under 4 levels (float rounding across machines and thread counts moves a handful of pixels by
a level or two). After a deliberate change, look at the new pictures, then
``python -m bench.golden``.
"""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from bench import golden

MEAN_LEVELS = 0.5
P999_LEVELS = 4.0


@pytest.mark.parametrize(("frame", "op"), golden.CASES, ids=lambda v: str(v))
def test_default_looks_as_its_golden_picture(frame: str, op: str) -> None:
    path = golden.GOLDEN_DIR / golden.case_name(frame, op)
    expected = np.asarray(Image.open(path).convert("RGB"), np.float32)
    actual = golden.render_case(frame, op).astype(np.float32)
    assert actual.shape == expected.shape
    diff = np.abs(actual - expected)
    assert diff.mean() < MEAN_LEVELS, f"{path.name}: mean difference {diff.mean():.2f} levels"
    p999 = float(np.percentile(diff.max(axis=2), 99.9))
    assert p999 < P999_LEVELS, f"{path.name}: 99.9th percentile {p999:.1f} levels"


def test_a_changed_look_is_caught() -> None:
    """The tolerance is tight enough for a γ of 1.1 instead of 1 (a barely visible change)."""
    frame, op = golden.CASES[0]
    expected = np.asarray(Image.open(golden.GOLDEN_DIR / golden.case_name(frame, op)), np.float32)
    from bench import corpus
    from service import pipeline

    source = {f.name: f for f in corpus.find_frames(corpus.CI_DIR)}[frame]
    f = source.read()
    out = pipeline.run(f, [{"op": op, "params": {"gamma": 1.1}}])
    actual = golden.picture(out.buffers["beauty"], golden.exposure(f)).astype(np.float32)
    diff = np.abs(actual - expected)
    assert diff.mean() >= MEAN_LEVELS or np.percentile(diff.max(axis=2), 99.9) >= P999_LEVELS
