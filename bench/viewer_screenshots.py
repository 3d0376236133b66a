"""Screenshots of the web viewer for the README: a Blender Cycles frame and a Depict render.

Run: ``.venv/bin/python -m bench.viewer_screenshots``. Needs Debian's ``chromium`` and, for the
Blender frame, ``blender`` (the fixture scene of tests/fixtures/blender rendered at 960x720).
Writes docs/images/viewer_blender.png and docs/images/viewer_depict.png (1600x900).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Any

from bench.viewer_browser import CHROMIUM, previews, viewer, wait_preview
from gbuffer.io import write
from gbuffer.render import load_mesh, render

ROOT = Path(__file__).resolve().parent.parent
IMAGES = ROOT / "docs" / "images"
FIXTURE_SCRIPT = ROOT / "tests" / "fixtures" / "blender" / "make_fixture.py"
ENV = {"DEPICT_WORKERS": "1", "DEPICT_TIMEOUT_S": "600"}


def blender_frame(work: Path) -> Path | None:
    """The Blender fixture scene rendered by Cycles at 960x720, or None without Blender."""
    blender = shutil.which("blender")
    if blender is None:
        print("blender is absent: no Blender screenshot")
        return None
    env = {**os.environ, "DEPICT_FIXTURE_SIZE": "960x720"}
    args = [blender, "-b", "--factory-startup", "--python", str(FIXTURE_SCRIPT), "--", str(work)]
    subprocess.run(args, env=env, check=True, capture_output=True)
    return work / "cycles_multilayer.exr"


def tune(page: Any, preset: str, edits: dict[str, str]) -> None:
    """Choose a built-in preset, then move sliders (``[data-param] -> slider value 0..1000``)."""
    seen = previews(page)
    page.select_option("#presets", f"b:{preset}")
    wait_preview(page, seen)
    for selector, value in edits.items():
        seen = previews(page)
        page.locator(f"{selector} input[type=range]").fill(value)
        wait_preview(page, seen)


def shoot(frame: Path, target: Path, preset: str, edits: dict[str, str]) -> None:
    with viewer(frame, ENV) as (page, _):
        tune(page, preset, edits)
        page.wait_for_timeout(300)  # the last picture decoded and laid out
        page.screenshot(path=str(target))
    print(f"wrote {target}")


def main() -> None:
    if not Path(CHROMIUM).is_file():
        print(f"Chromium is absent ({CHROMIUM}; apt-get install chromium): no screenshots")
        return
    work = Path(tempfile.mkdtemp(prefix="viewer-shots-"))
    try:
        blender = blender_frame(work)
        if blender is not None:
            gamma = '[data-op="radiance_scaling"] [data-param="gamma"]'
            shoot(blender, IMAGES / "viewer_blender.png", "Radiance Scaling", {gamma: "700"})
        depict = work / "spot.exr"
        write(render(load_mesh(ROOT / "examples" / "spot.obj"), 1280, 960), depict)
        gamma = '[data-op="light_alignment"] [data-param="gamma"]'
        shoot(depict, IMAGES / "viewer_depict.png", "Light Alignment", {gamma: "300"})
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
