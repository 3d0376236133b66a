"""What a :class:`gbuffer.frame.Frame` built in Python accepts (the readers and the renderer build
right ones; a script's arrays may be anything), and which of its pixels hold a surface."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pytest

from gbuffer.camera import Camera, Projection
from gbuffer.frame import NORMAL_COMPONENT_MAX, Frame, normal_faults
from service import pipeline
from tests.exr_factory import make_scene


def sphere() -> dict[str, np.ndarray]:
    s = make_scene(24, 32)
    names = ("beauty", "normal", "depth", "albedo", "diffuse", "specular")
    return {n: np.asarray(getattr(s, n), np.float32) for n in names}


@pytest.mark.parametrize(
    ("name", "value", "words"),
    [
        ("beauty", lambda b: b[..., 0].copy(), "'beauty' must be (H, W, 3), got (24, 32)"),
        ("beauty", lambda b: np.dstack([b, b[..., :1]]), "must be (H, W, 3), got (24, 32, 4)"),
        ("depth", lambda d: np.dstack([d] * 3), "'depth' must be (H, W), got (24, 32, 3)"),
        ("depth", lambda d: d.astype(np.complex64), "real numbers, got complex64"),
        ("normal", lambda n: n.astype(object), "'normal' must be an array of real numbers"),
        ("depth", lambda d: d.tolist(), "real numbers, got list"),
        ("mine", lambda _: np.zeros((24, 32, 2, 2)), "'mine' must be (H, W) or (H, W, C)"),
    ],
)
def test_a_buffer_of_the_wrong_kind_is_named(name: str, value: Any, words: str) -> None:
    """(Wrong channel counts went on to NumPy's broadcasting errors inside the operators,
    complex values lost their imaginary part with a warning.)"""
    buffers = sphere()
    buffers[name] = value(buffers.get(name, buffers["depth"]))
    with pytest.raises(ValueError, match=re.escape(words)):
        Frame(buffers=buffers)


@pytest.mark.parametrize("size", [(0, 0), (32, -24), (32.5, 24), (32,)])
def test_a_display_window_of_no_size_is_refused(size: Any) -> None:
    """(0, 0) divided by zero in five operators and gave NaN in Light Alignment."""
    with pytest.raises(ValueError, match=r"display_size must be \(width, height\), two whole"):
        Frame(buffers=sphere(), display_size=size)


def test_depth_of_zero_or_below_is_no_surface() -> None:
    """As files are read: a script's negative depth covered its pixels, and Radiance Scaling and
    unsharp masking failed on a negative "sigma_scene", Apparent Relief shaded them."""
    buffers = sphere()
    on = np.isfinite(buffers["depth"])
    assert on.any() and not on.all()
    depth = np.where(on, -buffers["depth"], np.inf).astype(np.float32)
    depth[0, 0] = 0.0
    frame = Frame(buffers={**buffers, "depth": depth})
    assert not frame.covered().any() and not (frame.mask > 0).any()
    assert Frame(buffers=buffers).covered().sum() == on.sum()
    for op in ("radiance_scaling", "unsharp_masking", "apparent_relief", "light_alignment"):
        out = pipeline.run(frame, [{"op": op}])
        assert np.array_equal(out.buffers["beauty"], frame.buffers["beauty"]), op


def test_a_depth_of_minus_infinity_is_named_by_the_score() -> None:
    buffers = sphere()
    depth = -buffers["depth"]  # (the background's +inf becomes -inf)
    with pytest.raises(Exception, match="depth contains -inf: depth is positive"):
        pipeline.run(Frame(buffers={**buffers, "depth": depth}), [{"op": "congruence"}])


#: The operators that read the frame's normals at every pixel of a window, background included.
NORMAL_READERS = ("light_alignment", "exaggerated_shading", "light_warping")


@pytest.mark.parametrize("op", NORMAL_READERS)
def test_nan_normals_off_the_surface_change_nothing(op: str) -> None:
    """A script's frame may hold anything off the surface (a compositor's normalise of a zero
    vector gives NaN): Light Alignment's pyramid spread it to every covered pixel (the whole
    beauty NaN), Exaggerated Shading and Light Warping refused the frame."""
    buffers = sphere()
    off = ~np.isfinite(buffers["depth"])
    assert off.any() and (buffers["normal"][off] == 0).all()
    nan = buffers["normal"].copy()
    nan[off] = np.nan
    want = pipeline.run(Frame(buffers=buffers), [{"op": op}]).buffers["beauty"]
    got = pipeline.run(Frame(buffers={**buffers, "normal": nan}), [{"op": op}]).buffers["beauty"]
    assert np.isfinite(want).all()
    assert np.array_equal(got, want)


@pytest.mark.parametrize("op", NORMAL_READERS)
def test_nan_normals_on_the_surface_are_counted(op: str) -> None:
    """As a file's are refused: Light Alignment made every covered pixel NaN from a few."""
    buffers = sphere()
    ys, xs = np.nonzero(np.isfinite(buffers["depth"]))
    buffers["normal"][ys[:3], xs[:3]] = [np.nan, 0.0, np.inf]
    with pytest.raises(Exception, match=f"{op}: the normal is NaN or Inf at 3 covered pixels"):
        pipeline.run(Frame(buffers=buffers), [{"op": op}])


@pytest.mark.parametrize(
    ("value", "past", "bad"),
    [
        (np.nan, False, True),
        (np.inf, True, True),
        (-np.inf, True, True),
        (NORMAL_COMPONENT_MAX, False, False),
        (-np.nextafter(np.float32(NORMAL_COMPONENT_MAX), np.float32(3.0)), True, False),
        (np.float32(1e20), True, False),
    ],
)
@pytest.mark.parametrize("where", [(0, 0, 0), (517, 900, 1), (-1, -1, 2)])
def test_normal_faults_are_found_in_any_strip(
    value: float, past: bool, bad: bool, where: tuple[int, int, int]
) -> None:
    """One compiled pass over strips of rows tells a component past ±2 and one not finite
    apart, wherever it is (the first pixel, a middle strip, the last component)."""
    normal = np.random.default_rng(3).uniform(-1, 1, (600, 1001, 3)).astype(np.float32)
    assert normal_faults(normal) == (False, False)
    normal[where] = value
    assert normal_faults(normal) == (past, bad)
    assert normal_faults(normal[::2]) == (past and where[0] % 2 == 0, bad and where[0] % 2 == 0)
    assert normal_faults(np.zeros((0, 4, 3), np.float32)) == (False, False)


@pytest.mark.parametrize(
    "op", ["curvature", "light_alignment", "apparent_relief", "unsharp_masking"]
)
def test_normals_far_from_unit_on_the_surface_are_counted(op: str) -> None:
    """Normals of 1e20 made curvature, Light Alignment and Apparent Relief NaN, and unsharp
    masking say 'gain_map must be finite' (it was given none); off the surface they may be
    anything, and normals a little longer than 1 (a renderer's interpolated ones) are taken."""
    buffers = sphere()
    on = np.isfinite(buffers["depth"])
    ys, xs = np.nonzero(on)
    far = buffers["normal"].copy()
    far[ys[:5], xs[:5]] *= np.float32(1e20)
    with pytest.raises(Exception, match=r"the normal is not a unit vector at 5 covered pixels"):
        pipeline.run(Frame(buffers={**buffers, "normal": far}), [{"op": op}])
    want = pipeline.run(Frame(buffers=buffers), [{"op": op}]).buffers["beauty"]
    off = buffers["normal"].copy()
    off[~on] = np.float32(1e30)
    got = pipeline.run(Frame(buffers={**buffers, "normal": off}), [{"op": op}]).buffers["beauty"]
    assert np.array_equal(got, want)
    longer = buffers["normal"] * np.float32(1.05)
    out = pipeline.run(Frame(buffers={**buffers, "normal": longer}), [{"op": op}])
    assert np.isfinite(out.buffers["beauty"]).all()


@pytest.mark.parametrize("projection", ["perspective", "orthographic", None])
def test_view_vectors_point_at_the_eye_in_every_strip(projection: Projection | None) -> None:
    """The unit vectors towards the eye, made by strips of rows: −P/|P| of each pixel's point
    on the image plane (perspective, a data window inside the display window), (0, 0, 1)
    orthographic and without a camera."""
    camera = None
    if projection is not None:
        camera = Camera(None, projection, fov_y_deg=50.0, ortho_height=2.0)
    shape, display, origin = (700, 1301), (1400, 800), (60, 41)
    frame = Frame(
        buffers={"depth": np.ones(shape, np.float32)},
        camera=camera,
        display_size=display,
        origin=origin,
    )
    view = frame.view_vectors()
    if projection != "perspective":
        assert np.array_equal(view, np.broadcast_to(np.array([0, 0, 1], np.float32), (*shape, 3)))
        return
    assert camera is not None
    xs, ys = camera.image_coordinates(shape, display, origin)
    eye = np.dstack(np.broadcast_arrays(-xs[None, :], ys[:, None], np.ones(shape))).astype(float)
    np.testing.assert_allclose(view, eye / np.linalg.norm(eye, axis=2, keepdims=True), atol=1e-6)
