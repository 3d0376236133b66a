"""``depict --version`` and ``depict --help`` answer without importing the heavy libraries (the
frame I/O, the maths, the HTTP client): what they import is checked, not how long they take."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from service.version import version

HEAVY = ("numpy", "cv2", "numba", "scipy", "OpenEXR", "httpx", "fastapi", "pydantic", "gbuffer")

PROBE = """
import contextlib, io, json, sys
from service.cli import main
out = io.StringIO()
with contextlib.redirect_stdout(out):
    try:
        main(sys.argv[1:])
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
