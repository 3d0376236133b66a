"""``depict --version`` and ``depict --help`` answer without importing the heavy libraries (the
frame I/O, the maths, the HTTP client), and ``depict preview`` without the operators and Numba:
what they import is checked, not how long they take."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from service.version import version

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("numpy", "cv2", "numba", "scipy", "OpenEXR", "httpx", "fastapi", "pydantic", "gbuffer")

PROBE = """
import contextlib, io, json, sys
from service.cli import main
out = io.StringIO()
with contextlib.redirect_stdout(out):
    try:
        code = main(sys.argv[1:])
    except SystemExit as exc:
        code = exc.code
print(json.dumps({"code": code, "out": out.getvalue(), "modules": sorted(sys.modules)}))
"""


@pytest.mark.parametrize("flag", ["--version", "--help"])
def test_version_and_help_import_nothing_heavy(flag: str) -> None:
    run = subprocess.run(
        [sys.executable, "-c", PROBE, flag], capture_output=True, text=True, check=True
    )
    answer = json.loads(run.stdout.splitlines()[-1])
    assert answer["code"] == 0
    loaded = {m.split(".")[0] for m in answer["modules"]}
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))
    if flag == "--version":
        assert answer["out"].strip() == f"depict {version()}"
    else:
        assert "enhance" in answer["out"] and "compare" in answer["out"]


def test_a_deferred_command_still_has_its_arguments() -> None:
    run = subprocess.run(
        [sys.executable, "-c", PROBE, "compare", "--help"], capture_output=True, text=True
    )
    answer = json.loads(run.stdout.splitlines()[-1])
    assert answer["code"] == 0 and "--albedo {white,frame}" in answer["out"]


def test_preview_loads_no_operator_and_no_numba(tmp_path: Path) -> None:
    """Reading and showing a frame needs neither the operators nor their compiled kernels."""
    src = ROOT / "tests" / "fixtures" / "blender" / "cycles_multilayer.exr"
    argv = ["preview", str(src), "-o", str(tmp_path / "p.png")]
    run = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True)
    answer = json.loads(run.stdout.splitlines()[-1])
    assert answer["code"] == 0 and (tmp_path / "p.png").is_file()
    loaded = {m.split(".")[0] for m in answer["modules"]}
    assert "numba" not in loaded and "service.registry" not in answer["modules"]
