"""The README's examples run as written: every block after a ``<!-- README-TEST: NAME -->`` line.

The shell blocks run with bash in a fresh folder that sees the repository's ``examples/`` and
``tests/`` (the tour starts from the repository root), the Python blocks with this interpreter;
the HTTP blocks against a real ``depict serve`` with an API key, its address put in place of the
README's ``http://127.0.0.1:8000``.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

from tests.live_server import live_server

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
BLOCK = re.compile(r"<!-- README-TEST: (\w+) -->\n```(\w+)\n(.*?)```", re.S)
KEY = "secret"
BIN = str(Path(sys.executable).parent)


def blocks() -> dict[str, tuple[str, str]]:
    """README-TEST name -> (language, code)."""
    return {name: (lang, code) for name, lang, code in BLOCK.findall(README.read_text())}


def folder(tmp: Path) -> Path:
    for name in ("examples", "tests"):
        (tmp / name).symlink_to(ROOT / name)
    return tmp


def run(tmp: Path, name: str, url: str | None = None) -> subprocess.CompletedProcess[str]:
    lang, code = blocks()[name]
    if url is not None:
        code = code.replace("http://127.0.0.1:8000", url)
    env = {**os.environ, "PATH": f"{BIN}:{os.environ['PATH']}", "KEY": KEY}
    env.pop("DEPICT_SERVER", None)
    if lang == "sh":
        cmd = ["bash", "-e", "-o", "pipefail", "-c", code]
    else:
        cmd = [sys.executable, "-c", code]
    done = subprocess.run(cmd, cwd=tmp, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"README block {name!r} failed:\n{done.stdout}\n{done.stderr}"
    return done


def test_the_readme_marks_its_tested_blocks() -> None:
    assert set(blocks()) == {"tour", "python", "http", "client", "masks"}


def test_tour(tmp_path: Path) -> None:
    done = run(folder(tmp_path), "tour")
    for name in ("spot_lla.png", "scores.png", "sheet.png", "shot_out.exr", "shot_out.png"):
        assert (tmp_path / name).is_file(), name
    assert "camera source: solved from ViewLayer.Position.X,Y,Z" in done.stdout
    assert "depict: result in ViewLayer.Depict" in done.stdout


def test_masks(tmp_path: Path) -> None:
    done = run(folder(tmp_path), "masks")
    assert "cryptomatte ViewLayer.CryptoObject (4 ranks)" in done.stdout
    assert "suzanne.png (cryptomatte:Suzanne: 2783 pixels inside, 533 partly)" in done.stdout
    for name in ("suzanne.png", "ids.png", "hero.exr"):
        assert (tmp_path / name).is_file(), name


def shot(tmp: Path) -> Path:
    shutil.copy(ROOT / "tests" / "fixtures" / "blender" / "cycles_multilayer.exr", tmp / "shot.exr")
    shutil.copy(ROOT / "tests" / "fixtures" / "blender" / "camera.json", tmp / "cam.json")
    return tmp


def test_python_api(tmp_path: Path) -> None:
    done = run(shot(tmp_path), "python")
    assert (tmp_path / "shot_out.exr").is_file()
    assert "(120, 160, 3)" in done.stdout


def test_http_and_client(tmp_path: Path) -> None:
    shot(tmp_path)
    with live_server({"DEPICT_API_KEY": KEY, "DEPICT_WORKERS": "1"}) as server:
        done = run(tmp_path, "http", server.url)
        assert '"version"' in done.stdout
        run(tmp_path, "client", server.url)
        # the form field is the JSON text: a file upload in its place is refused
        bad = subprocess.run(
            ["curl", "-s", "-o", "/dev/null", "-w", "%{http_code}", "-H", f"Authorization: "
             f"Bearer {KEY}", "-F", "file=@shot.exr", "-F", "camera=@cam.json",
             f"{server.url}/v1/enhance"],
            cwd=tmp_path, capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert bad.stdout == "422"
    for name in ("shot_usm.exr", "shot_look.exr", "shot_out.exr"):
        assert (tmp_path / name).is_file(), name
