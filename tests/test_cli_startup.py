"""``depict --version`` and ``depict --help`` answer without importing the heavy libraries (the
frame I/O, the maths, the HTTP client), and ``depict preview`` without the operators and Numba:
what they import is checked, not how long they take."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

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


def probed(code: str, *args: str | Path, env: dict[str, str] | None = None) -> Any:
    """What the Python ``code`` printed last, as JSON, run in a process of its own from the
    repository's root with ``args`` (its stderr's end shown if it fails)."""
    run = subprocess.run(
        [sys.executable, "-c", code, *map(str, args)],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    return json.loads(run.stdout.splitlines()[-1])


@pytest.mark.parametrize("flag", ["--version", "--help"])
def test_version_and_help_import_nothing_heavy(flag: str) -> None:
    answer = probed(PROBE, flag)
    assert answer["code"] == 0
    loaded = {m.split(".")[0] for m in answer["modules"]}
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))
    if flag == "--version":
        assert answer["out"].strip() == f"depict {version()}"
    else:
        assert "enhance" in answer["out"] and "compare" in answer["out"]


def test_a_deferred_command_still_has_its_arguments() -> None:
    answer = probed(PROBE, "compare", "--help")
    assert answer["code"] == 0 and "--albedo {white,frame}" in answer["out"]


FRAME = ROOT / "tests" / "fixtures" / "blender" / "cycles_multilayer.exr"


def _modules_of(*argv: str) -> tuple[set[str], list[str]]:
    """The top-level packages and the modules a successful ``depict *argv`` loaded."""
    answer = probed(PROBE, *argv)
    assert answer["code"] == 0
    return {m.split(".")[0] for m in answer["modules"]}, answer["modules"]


def test_preview_loads_no_operator_and_no_numba(tmp_path: Path) -> None:
    """Reading and showing a frame needs neither the operators nor their compiled kernels."""
    loaded, modules = _modules_of("preview", str(FRAME), "-o", str(tmp_path / "p.png"))
    assert (tmp_path / "p.png").is_file()
    assert "numba" not in loaded and "service.registry" not in modules


def test_enhance_loads_no_image_library_it_does_not_use(tmp_path: Path) -> None:
    """``depict enhance`` of an EXR in the standard spaces loads neither OpenImageIO (PNG and
    image parameters) nor OpenColorIO (named spaces, views): 30 MiB and 40 ms of every run."""
    loaded, _ = _modules_of("enhance", str(FRAME), "-o", str(tmp_path / "out.exr"))
    assert (tmp_path / "out.exr").is_file()
    assert "numba" in loaded and not loaded & {"OpenImageIO", "PyOpenColorIO"}


COMPILED_PROBE = """
import importlib.util, json, sys
from pathlib import Path
from service import pipeline
from gbuffer.io import read
import numba.core.typing.context, numba.np.arraymath  # what a kernel's first call loads
root = Path(sys.prefix).resolve()
missing = []
for name, module in list(sys.modules.items()):
    source = getattr(module, "__file__", None) or ""
    if not source.endswith(".py") or not Path(source).resolve().is_relative_to(root):
        continue
    cached = Path(importlib.util.cache_from_source(source))
    if not cached.exists() or cached.stat().st_mtime < Path(source).stat().st_mtime:
        missing.append(name)
print(json.dumps(sorted(missing)))
"""


def test_the_install_compiled_the_bytecode_of_the_enhance_path() -> None:
    """``make install`` compiles the bytecode of the environment's modules (uv's
    ``--compile-bytecode``; Depict's own packages by ``compileall``, which edits make stale, so
    they are not checked): a process that may not write ``__pycache__`` (a read-only install,
    the container's user, ``PYTHONDONTWRITEBYTECODE``) would otherwise compile the 800 modules
    of ``depict enhance`` from source again, about a second each time."""
    env = {"PYTHONDONTWRITEBYTECODE": "1", "PYOPENGL_PLATFORM": "osmesa"}
    missing = probed(COMPILED_PROBE, env=env)
    assert not missing, f"{len(missing)} modules without bytecode, e.g. {missing[:5]}"


def test_the_executable_ends_without_teardown_but_keeps_output_and_exit_code(
    tmp_path: Path,
) -> None:
    """The ``depict`` executable (:func:`service.cli.run`) ends the process without tearing the
    interpreter down: what it printed into a pipe still arrives, and the exit code is main's."""
    depict = str(Path(sys.executable).parent / "depict")
    listed = subprocess.run([depict, "ops"], capture_output=True, text=True)
    assert listed.returncode == 0 and "radiance_scaling" in listed.stdout
    missing = tmp_path / "missing.exr"
    failed = subprocess.run(
        [depict, "enhance", str(missing), "-o", str(tmp_path / "out.exr")],
        capture_output=True,
        text=True,
    )
    assert failed.returncode == 2
    assert failed.stderr.startswith("depict: error:") and len(failed.stderr.splitlines()) == 1


PREPARE_PROBE = """
import json, sys, threading
import service.enhance as enhance
from service import pipeline
from ops.jit import prepare
loaded = "numba.np.arraymath" in sys.modules
names = []
read_for = enhance.read_for
def reading(*args, **kwargs):  # the threads alive as the frame starts to decode
    names.extend(t.name for t in threading.enumerate())
    return read_for(*args, **kwargs)
enhance.read_for = reading
enhance.enhance(sys.argv[1], sys.argv[2], pipeline.compile([{"op": "curvature"}]))
print(json.dumps({"before": loaded, "after": "numba.np.arraymath" in sys.modules, "names": names}))
"""


def test_enhance_readies_numbas_compiler_while_the_frame_decodes(tmp_path: Path) -> None:
    """The first kernel of a process loads Numba's registries (~0.3 s, SciPy's linear algebra
    among them); ``enhance`` has a thread of its own load them (``ops.jit.prepare``) while the
    frame decodes."""
    out = tmp_path / "out.exr"
    answer = probed(PREPARE_PROBE, FRAME, out)
    assert not answer["before"] and answer["after"] and out.is_file()
    assert "depict-jit-prepare" in answer["names"]


READ_AHEAD_PROBE = """
import json, sys, threading
import service.cli.frames as frames
import service.enhance as enhance
from service.cli import main
events = []
def note(what):
    events.append([what, threading.current_thread().name])
read_for, steps = enhance.read_for, frames.steps
def reading(*args, **kwargs):
    note("read")
    return read_for(*args, **kwargs)
def checking(args):
    note("pipeline checked")
    return steps(args)
enhance.read_for, frames.steps = reading, checking
code = main(["enhance", sys.argv[1], "-o", sys.argv[2]])
print(json.dumps({"code": code, "events": events, "prepared": "numba.np.arraymath" in sys.modules}))
"""


def test_enhance_decodes_the_first_input_while_it_loads_the_operators(tmp_path: Path) -> None:
    """``depict enhance`` starts reading its first input on a thread of its own before it imports
    the operators (and Numba) and checks the pipeline, which take about half a second: the
    OpenEXR library decodes meanwhile, without Python's lock. Numba's start-up follows beside the
    rest of the read, and the frame is enhanced as before."""
    out = tmp_path / "out.exr"
    answer = probed(READ_AHEAD_PROBE, FRAME, out)
    assert answer["code"] == 0 and out.is_file() and answer["prepared"]
    assert answer["events"] == [["read", "depict-read-ahead"], ["pipeline checked", "MainThread"]]


SEQUENCE_PROBE = """
import json, sys, threading
from pathlib import Path
import service.enhance as enhance
from service.cli import main
events = []
read_for, write_exr = enhance.read_for, enhance.write_exr
def reading(path, *args, **kwargs):
    events.append(["read", Path(path).name, threading.current_thread().name])
    return read_for(path, *args, **kwargs)
def writing(frame, path, *args, **kwargs):
    done = write_exr(frame, path, *args, **kwargs)
    events.append(["written", Path(path).name, threading.current_thread().name])
    return done
enhance.read_for, enhance.write_exr = reading, writing
code = main(["enhance", *sys.argv[1:-1], "-o", sys.argv[-1]])
print(json.dumps({"code": code, "events": events}))
"""


def test_enhance_of_several_files_reads_the_next_while_it_writes_one(tmp_path: Path) -> None:
    """``depict enhance`` of several files starts reading the next input once the operators
    have run on one and its buffers are let go, while that one's result is written (the memory
    the frame held is free then). Each output is the one a single file gives."""
    inputs = []
    for name in ("a.exr", "b.exr"):
        inputs.append(tmp_path / name)
        inputs[-1].write_bytes(FRAME.read_bytes())
    outs = tmp_path / "out"
    outs.mkdir()
    answer = probed(SEQUENCE_PROBE, *inputs, outs)
    assert answer["code"] == 0
    events = answer["events"]
    assert events[0] == ["read", "a.exr", "depict-read-ahead"]
    assert events.index(["read", "b.exr", "depict-read-ahead"]) < events.index(
        ["written", "a.exr", "MainThread"]
    ), events
    single = tmp_path / "single.exr"
    assert probed(SEQUENCE_PROBE, inputs[1], single)["code"] == 0
    assert (outs / "b.exr").read_bytes() == single.read_bytes()
