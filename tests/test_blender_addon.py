"""The Blender add-on (integrations/blender/depict_blender.py) in Debian's headless Blender.

tests/blender/addon_driver.py installs it with Blender's own "Install Add-on" operator, renders a
small Cycles scene, runs ``bpy.ops.depict.enhance`` and renders the compositor; these tests read
its report and the files it made with OpenEXR. Three ways: the local ``depict`` on PATH, a real
Depict server (``DEPICT_SERVER``) with no ``depict`` on PATH, and neither (a clear error).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import OpenEXR
import pytest

import gbuffer
from service.masks import matte
from tests.live_server import live_server

ROOT = Path(__file__).resolve().parents[1]
ADDON = ROOT / "integrations" / "blender" / "depict_blender.py"
DRIVER = ROOT / "tests" / "blender" / "addon_driver.py"
BLENDER = shutil.which("blender")
PIPELINE = '{"steps": [{"op": "radiance_scaling", "params": {"preset": "paper", "gamma": 2}}]}'

pytestmark = pytest.mark.skipif(BLENDER is None, reason="Debian's blender is not installed")


def drive(
    tmp: Path,
    path: str,
    server: str | None = None,
    pipeline: str = PIPELINE,
    scene: str = "one-layer",
) -> dict[str, Any]:
    """Run the driver with ``PATH`` = ``path``; its report (and the files it left in ``tmp``).
    ``scene``: ``two-layers`` adds a view layer with more passes beside the active one."""
    assert BLENDER is not None
    env = {k: v for k, v in os.environ.items() if not k.startswith("DEPICT_")}
    env.update(PATH=path, BLENDER_USER_SCRIPTS=str(tmp / "scripts"), TMPDIR=str(tmp))
    if server:
        env["DEPICT_SERVER"] = server
    cmd = [BLENDER, "-b", "--factory-startup", "--python", str(DRIVER), "--"]
    run = subprocess.run(
        [*cmd, str(ADDON), str(tmp), pipeline, scene],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    report_file = tmp / "report.json"
    assert report_file.is_file(), run.stdout[-3000:] + run.stderr[-3000:]
    return dict(json.loads(report_file.read_text()))


def check_result(tmp: Path, report: dict[str, Any]) -> Path:
    assert "error" not in report, report["error"]
    assert report["enabled"] and report["operator"]
    assert report["panels"] == ["DEPICT_PT_render", "DEPICT_PT_image"]
    assert report["result"] == report["again"] == ["FINISHED"]
    image = report["image"]
    assert image["name"] == "Depict Result" and image["type"] == "MULTILAYER"
    assert "Depict" in report["node_outputs"] and report["composite_from"] == ["Depict"]
    out = Path(image["filepath"])
    with OpenEXR.File(str(out), separate_channels=True) as f:  # every part (layout "part")
        header = {k: v for p in f.parts for k, v in p.header.items()}
        names = {n for p in f.parts for n in p.channels}
    assert {f"ViewLayer.Depict.{c}" for c in "RGBA"} <= names
    steps = json.loads(header["depict/pipeline"])["steps"]
    assert steps[0]["op"] == "radiance_scaling" and steps[0]["params"]["gamma"] == 2
    assert header["depict/cameraSource"].startswith("given")
    # the add-on's camera JSON (sensor fit, resolution) puts every Position on its pixel
    frame = gbuffer.read(out)
    assert frame.camera is not None and frame.camera.fit is not None
    assert frame.camera.fit["rms_px"] < 0.01
    depict, combined = (
        cv2.imread(str(tmp / f"compositor_{p}.png")) for p in ("depict", "combined")
    )
    assert depict is not None and combined is not None and depict.shape == (90, 160, 3)
    assert float(np.abs(depict.astype(int) - combined).mean()) > 0.5
    return out


def test_addon_with_the_local_depict(tmp_path: Path) -> None:
    venv_bin = str(Path(sys.executable).parent)
    report = drive(tmp_path, f"{venv_bin}:/usr/bin:/bin")
    check_result(tmp_path, report)
    names = [s["id"] for s in report["settings"]]
    assert {"operator", "gamma", "scenario", "amount", "mask", "pipeline", "compositor"} <= set(
        names
    )


def test_addon_mask_switches_cryptomatte_on_and_changes_only_suzanne(tmp_path: Path) -> None:
    venv_bin = str(Path(sys.executable).parent)
    masked = PIPELINE.replace('"gamma": 2}', '"gamma": 2, "mask": "cryptomatte:Suzanne"}')
    report = drive(tmp_path, f"{venv_bin}:/usr/bin:/bin", pipeline=masked)
    assert "error" not in report, report["error"]
    assert report["result"] == report["again"] == ["FINISHED"]
    frame = gbuffer.read(report["image"]["filepath"])
    m = matte(frame, "cryptomatte:Suzanne")
    assert (m >= 1).sum() > 100  # the add-on switched the Cryptomatte passes on
    depict, combined = frame.layer("ViewLayer.Depict"), frame.layer("ViewLayer.Combined")
    after, before = (np.dstack([layer[c] for c in "RGB"]) for layer in (depict, combined))
    changed = (after != before).any(axis=-1)
    assert changed.sum() > 50 and not changed[m == 0].any()


def test_addon_enhances_the_active_view_layer_of_several(tmp_path: Path) -> None:
    """Beside the active view layer, one with more passes: Depict read that one (and the add-on
    then found no Depict pass in the active layer), having no way to be told which."""
    venv_bin = str(Path(sys.executable).parent)
    out = check_result(tmp_path, drive(tmp_path, f"{venv_bin}:/usr/bin:/bin", scene="two-layers"))
    with OpenEXR.File(str(out), separate_channels=True) as f:
        names = {n for p in f.parts for n in p.channels}
    assert "Another.AO.R" in names and not any(n.startswith("Another.Depict") for n in names)


def test_addon_with_a_depict_server(tmp_path: Path) -> None:
    with live_server({"DEPICT_WORKERS": "1"}) as server:
        report = drive(tmp_path, "/usr/bin:/bin", server=server.url, scene="two-layers")
        logs = server.logs()
    out = check_result(tmp_path, report)
    assert '"path": "/v1/enhance"' in logs and '"status": 200' in logs
    with OpenEXR.File(str(out), separate_channels=True) as f:
        assert f.parts[-1].header["depict/input"] == "render.exr"


def test_addon_without_depict_says_what_to_do(tmp_path: Path) -> None:
    report = drive(tmp_path, "/usr/bin:/bin")
    assert "depict is not on PATH" in report["error"]
    assert "Depict server" in report["error"]
