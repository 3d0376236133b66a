"""The ``depict`` command line's errors and warnings, in process: each error one line
``depict: error: ...`` on stderr, exit code 2, no traceback, nothing half-written; each warning
one line ``depict: warning: ...``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from service.scene import NOTHING_SEEN
from tests.exr_factory import TORN_MESH, render_with_nan
from tests.test_cli import SPOT, H, W, depict, render_spot


@pytest.fixture(scope="module")
def exr(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return render_spot(tmp_path_factory.mktemp("cli"))


# -- errors -------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def not_exr(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("bad") / "bad.exr"
    path.write_text("this is not an EXR file\n")
    return path


SHADOWS_OF_NOPE = ("--set", "signal=shadows", "--set", "unlit=nope")
ERRORS: dict[str, tuple[list[str], str]] = {
    "not an EXR": (["inspect", "{bad}"], "not an OpenEXR file"),
    "not an EXR (score)": (["score", "{bad}"], "not an OpenEXR file"),
    "missing input": (["inspect", "{missing}"], "missing.exr"),
    "missing input (enhance)": (["enhance", "{missing}", "-o", "{out}"], "missing.exr"),
    "unknown operator": (
        ["enhance", "{exr}", "-o", "{out}", "--op", "nope"],
        "unknown operator 'nope'",
    ),
    "unknown parameter": (
        ["enhance", "{exr}", "-o", "{out}", "--op", "radiance_scaling", "--set", "foo=1"],
        "unknown parameter 'foo'",
    ),
    "alpha out of range": (
        ["enhance", "{exr}", "-o", "{out}", "--op", "radiance_scaling", "--set", "alpha=2"],
        "alpha=2",
    ),
    "--set without --op": (["enhance", "{exr}", "-o", "{out}", "--set", "amount=1"], "--set"),
    "empty output": (["enhance", "{exr}", "-o", ""], "-o/--output: is empty; give a file name"),
    "NaN parameter": (  # (it said "Input should be less than or equal to 10000")
        ["enhance", "{exr}", "-o", "{out}", "--op", "radiance_scaling", "--set", "gamma=NaN"],
        "gamma=nan: Input should be a finite number",
    ),
    "true for a number": (  # (pydantic read it as 1: gamma = 1)
        ["enhance", "{exr}", "-o", "{out}", "--op", "light_alignment", "--set", "gamma=true"],
        "light_alignment: gamma=True: expected a number, not true or false",
    ),
    "false among numbers": (
        ["enhance", "{exr}", "-o", "{out}", "--op", "light_alignment", "--set", "sigmas=0,false"],
        "sigmas=[0, False]: expected a number, not true or false",
    ),
    "empty output (render)": (["render", "{exr}", "-o", " "], "-o/--output: is empty"),
    "a white past float32's reach": (  # (exit 0, NumPy overflow warnings, an inf scaling)
        ["enhance", "{exr}", "-o", "{out}", "--op", "unsharp_masking", "--set", "white=1e-40"],
        "unsharp_masking: white=1e-40: Input should be greater than or equal to 1e-30",
    ),
    "a JSON list that does not parse": (  # (split at its commas: "sigmas.0='[0.5'")
        ["enhance", "{exr}", "-o", "{out}", "--op", "light_alignment", "--set", "sigmas=[0.5,nan]"],
        "--set 'sigmas=[0.5,nan]': '[0.5,nan]' is not valid JSON (Expecting value",
    ),
    "a JSON list that does not parse (compare)": (
        ["compare", "{exr}", "--set", "light_alignment.sigmas=[0.5,"],
        "--set 'light_alignment.sigmas=[0.5,': '[0.5,' is not valid JSON",
    ),
    "no lobe": (  # (it scaled every lobe)
        ["enhance", "{exr}", "-o", "{out}", "--op", "radiance_scaling", "--set", "lobes=[]"],
        "lobes=[]: List should have at least 1 item",
    ),
    "empty server": (  # (an unset variable in --server "$FARM": it ran here)
        ["enhance", "{exr}", "-o", "{out}", "--server", ""],
        "--server: is empty; give the server's URL, or leave --server out to run here",
    ),
    "empty plot": (["compare", "{exr}", "--plot", ""], "--plot: is empty"),
    "a light that is not one": (
        ["enhance", "{exr}", "-o", "{out}", "--op", "light_alignment", "--set", "lights=1,2"],
        "light '1,2' is not of the form",
    ),
    "an operator's own error, named once": (
        ["enhance", "{exr}", "-o", "{out}", "--op", "unsharp_masking", *SHADOWS_OF_NOPE],
        "error: unsharp_masking: no RGB layer 'nope' (unlit)",
    ),
    "missing pipeline file": (
        ["enhance", "{exr}", "-o", "{out}", "--pipeline", "{missing}"],
        "pipeline",
    ),
    "pixel out of range": (["relief-pick", "{exr}", str(W + 10), "3"], "x="),
    "negative pixel": (["relief-pick", "{exr}", "3", "-1"], "y="),
    "arm size": (["arm", "-o", "{out}", "--size", "10"], "size"),
    "arm paint syntax": (["arm", "-o", "{out}", "--paint", "0.5"], "--paint"),
    "arm to a format it has no encoder for": (  # (a cv2.error traceback, exit 1)
        ["arm", "-o", "{out}"],
        "no .exr encoder for an 8-bit picture; use .png",
    ),
    "arm paint outside the descriptor's square": (  # (a black ARM, exit 0)
        ["arm", "-o", "{out}.png", "--paint", "nan,0"],
        "must be a descriptor (S1, S2), each in [-1, 1]",
    ),
    "arm size with paint": (
        ["arm", "-o", "{out}.png", "--size", "5", "--paint", "0,0"],
        "--size 5",
    ),
    "arm base without paint": (["arm", "-o", "{out}.png", "--base", "convex"], "give --paint"),
    "a pick on the background": (  # (it said "plane", S = (0, 0))
        ["relief-pick", "{exr}", "0", "0"],
        "pixel (0, 0) shows no surface",
    ),
    "a curvedness norm under float32's range": (  # (S was NaN, and the JSON invalid)
        ["relief-pick", "{exr}", str(W // 2), str(H // 2), "--curvedness-norm", "1e-320"],
        "curvedness_norm=1e-320: Input should be greater than or equal to 1e-06",
    ),
    "a light too bright for float32": (  # (a beauty of NaN, exit 0)
        ["render", "{mesh}", "-o", "{out}", "--light", "0,0,1*1e308"],
        "light intensity must be finite, >= 0 and at most 1e+15",
    ),
    "an azimuth of inf": (["render", "{mesh}", "-o", "{out}", "--azimuth", "inf"], "azimuth must"),
    "an elevation past 90": (  # (the service refused it; here the mesh was seen upside down)
        ["render", "{mesh}", "-o", "{out}", "--elevation", "120"],
        "elevation must be a finite number of degrees in [-90, 90], got 120.0",
    ),
    "a buffer mapped twice": (  # (the last --map was taken, without a word)
        ["score", "{exr}", "--map", "normal=N", "--map", "normal=P"],
        "normal is mapped twice",
    ),
    "a preview to a format with no writer": (  # (the error named the temporary file)
        ["preview", "{exr}", "-o", "{out}.txt"],
        "out.exr.txt: no picture format for .txt; use .png",
    ),
    "compare method": (["compare", "{exr}", "--methods", "lambert,foo"], "foo"),
    "compare of no method": (["compare", "{exr}", "--methods=,"], "name at least one method"),
    "a plot named for no format": (  # (after the whole comparison: "Format 'tmp'", sheet written)
        ["compare", "{exr}", "--directions", "1", "--sheet", "{out}", "--plot", "{out}.xyz"],
        "--plot {out}.xyz: a plot is written as ",
    ),
    "compare of a one-pixel render": (  # (the score's "depth must be at least 3x3")
        ["compare", "{mesh}", "--width", "1"],
        "a comparison renders at least 3x3 pixels",
    ),
    "missing -o": (["render", "{missing}"], "-o/--output"),
}


@pytest.mark.parametrize("case", list(ERRORS))
def test_errors_are_one_line_and_exit_2(
    case: str,
    exr: Path,
    not_exr: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv, needle = ERRORS[case]
    out = tmp_path / "out.exr"
    values = {"bad": not_exr, "missing": tmp_path / "missing.exr", "exr": exr, "out": out}
    values["mesh"] = SPOT
    assert depict(*[a.format(**values) for a in argv]) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("depict: error: "), lines[0]
    assert needle.format(**values) in lines[0]
    assert "Traceback" not in captured.err + captured.out
    assert not out.exists()  # nothing half-written


def test_a_reader_that_stops_early_is_no_error() -> None:
    """``depict ops | head -1``: the pipe closed, the command ends quietly as a C tool killed by
    SIGPIPE would (141; it was "depict: error: Broken pipe", exit 2)."""
    child = subprocess.Popen(
        [sys.executable, "-m", "service.cli", "ops"],
        cwd=Path(__file__).resolve().parent.parent,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert child.stdout is not None and child.stderr is not None
    child.stdout.close()  # (before it writes: its first line meets a closed pipe)
    err = child.stderr.read().decode()
    assert child.wait(timeout=120) == 141
    assert err == ""


@pytest.mark.parametrize(
    ("obj", "warning"),
    [  # (each was without a word: an empty frame; triangles dropped by the reader)
        ("v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n", NOTHING_SEEN),
        (
            TORN_MESH,
            "1 of the mesh's 3 triangles have a vertex with NaN or infinite coordinates: they "
            "are left out",
        ),
        (SPOT.read_text(), None),
    ],
)
def test_a_render_says_what_it_could_not_show(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], obj: str, warning: str | None
) -> None:
    mesh = tmp_path / "mesh.obj"
    mesh.write_text(obj)
    out = tmp_path / "r.exr"
    assert depict("render", mesh, "-o", out, "--width", "32", "--height", "24") == 0
    err = capsys.readouterr().err.splitlines()
    assert err == ([] if warning is None else [f"depict: warning: {warning}"])
    assert out.exists()


def test_compare_says_which_flags_its_input_does_not_use(
    exr: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A mesh's framing given with a frame, a frame's reading with a mesh: ignored, silently."""
    one = ("--methods", "lambert", "--directions", "1")
    assert depict("compare", exr, "--width", "100", *one) == 0
    assert capsys.readouterr().err.splitlines() == [
        f"depict: warning: --width: for a mesh input; it is a frame ({exr}): ignored"
    ]
    mesh = ("compare", SPOT, *one, "--width", "32", "--height", "24")
    assert depict(*mesh, "--preset", "blender", "--map", "depth=Z") == 0
    assert capsys.readouterr().err.splitlines() == [
        f"depict: warning: --preset, --map: for an EXR input; it is a mesh ({SPOT}): ignored"
    ]


def test_a_preview_of_a_file_without_a_beauty_names_its_layers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A luminance-only image (OpenEXR's Y, as its sample GrayRamps and LuminanceChroma files):
    the error listed the mapped buffers, none, so it ended in "available: " and nothing."""
    path = tmp_path / "grey.exr"
    ramp = np.tile(np.linspace(0.0, 1.0, 16, dtype=np.float32), (8, 1))
    OpenEXR.File({}, {"Y": ramp, "right.Y": ramp}).write(str(path))
    assert depict("preview", path, "-o", tmp_path / "p.png") == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("no buffer mapped; the file's layers: Y, right (--layer NAME)"), err
    assert depict("preview", path, "-o", tmp_path / "p.png", "--layer", "Y") == 0
    assert (tmp_path / "p.png").stat().st_size > 0


def test_a_set_value_is_json_a_comma_list_or_text() -> None:
    """Only a whole value that opens a JSON list or object must parse as one: a piece of a
    comma list may open with ``[`` (a mask's cryptomatte names are wildcards, ``[ab]*``)."""
    from service.cli.args import parse_value

    assert parse_value("[0.5,0.3]") == [0.5, 0.3] and parse_value("0.5,0.3") == [0.5, 0.3]
    assert parse_value("cryptomatte:rock,[ab]*") == ["cryptomatte:rock", "[ab]*"]
    assert parse_value("point:0,2,1") == ["point:0", 2, 1]
    with pytest.raises(ValueError, match=r"'\[0\.5,nan\]' is not valid JSON"):
        parse_value("[0.5,nan]")


def test_a_pick_on_a_hole_of_the_beauty_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A pixel whose beauty is NaN (a firefly) and depth finite: it is a hole, and the
    refusal said it had no finite depth there."""
    path = render_with_nan(tmp_path / "nan.exr", (64, 48), {"beauty": [(24, 32, 0, np.nan)]})
    capsys.readouterr()
    assert depict("relief-pick", path, "32", "24") == 2
    err = capsys.readouterr().err
    assert err == (
        "depict: error: pixel (32, 24) is a NaN or Inf pixel of the beauty (a hole the "
        "operators leave out): pick a pixel beside it\n"
    )


def test_a_comparison_of_nothing_in_view_says_its_scores_say_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A mesh of one degenerate triangle: every score 0, which said nothing, with exit 0 and
    no word (``score`` and ``render`` warned on the same input)."""
    mesh = tmp_path / "line.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    args = ["compare", mesh, "--directions", "1", "--methods", "lambert", "--width", "32"]
    assert depict(*args, "--height", "32") == 0
    assert "depict: warning: no pixel was scored: none is covered" in capsys.readouterr().err
