"""Local Light Alignment of light directions and of lights (LLA §4-6): the public entry points."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from ops.checks import IOR, LLA_GAMMA, LLA_SIGMA, check_sequence
from ops.filtering import F32, NormalPyramid
from ops.light_alignment._common import DEFAULT_GAMMA, GUIDES, Guide, SoA
from ops.light_alignment._stages import _align_full, _align_pyramid, _Inputs
from ops.pyramid import normalize_field
from ops.shading import Light, light_direction

__all__ = ["LIGHTS_PER_PASS", "align_components", "align_light", "align_lights"]

#: Lights aligned in one pass over the strips: a pass makes the fields and the view once for
#: its lights and holds every one's states and upsampled rows, so its memory grows with them
#: (six lights, two components, 1080p: 561 MiB at the peak all at once, 346 in pairs, 338 one
#: by one).
LIGHTS_PER_PASS = 2


def _check_sigmas(sigmas: Sequence[float], scales: int, name: str = "sigmas") -> list[float]:
    vals = [float(s) for s in sigmas]
    if len(vals) != scales - 1:
        raise ValueError(
            f"{name} must have one value per scale transition: {scales - 1} for {scales} "
            f"normal fields, got {len(vals)}"
        )
    return check_sequence(vals, LLA_SIGMA, name)


def _check_guide(guide: str) -> str:
    if guide not in GUIDES:
        raise ValueError(f"guide must be one of {', '.join(GUIDES)}; got {guide!r}")
    return guide


def _const_or_field(light_dir: np.ndarray, shape: tuple[int, int]) -> tuple[F32 | None, F32 | None]:
    arr = np.asarray(light_dir, np.float32)
    if arr.shape == (3,):
        norm = float(np.linalg.norm(arr))
        if not (math.isfinite(norm) and norm > 1e-12):
            raise ValueError("light_dir must be a finite non-zero vector")
        return (arr / norm).astype(np.float32), None
    if arr.shape != (*shape, 3):
        raise ValueError(f"light_dir must be (3,) or (H, W, 3) = {(*shape, 3)}, got {arr.shape}")
    return None, normalize_field(arr)


def align_components(
    light_dir: np.ndarray,
    normals: Sequence[np.ndarray] | NormalPyramid,
    components: Mapping[str, Sequence[float]],
    gamma: float = DEFAULT_GAMMA,
    view: np.ndarray | None = None,
    ior: float = 1.5,
    mask: np.ndarray | None = None,
) -> dict[str, F32]:
    """Aligned light directions for several shading components at once (LLA §4-6, Eq. 1).

    Parameters
    ----------
    light_dir : (3,) direction towards the light, or (H, W, 3) per pixel (point lights).
    normals : a :class:`~ops.filtering.NormalPyramid` (fast: coarse scales at low resolution)
        or the list [n_1, …, n_S] of (H, W, 3) fields (every scale at full resolution).
    components : guide name ("diffuse", "specular", "transmission") -> σ_1 … σ_{S−1}
        (finest first), each in [0, 1].
    gamma : γ of W_γ, in [0, 20].
    view : (H, W, 3) or (3,) unit directions towards the eye (needed by "specular" and
        "transmission").
    ior : index of refraction of the transmission guide, in (0, 10].
    mask : (H, W) coverage for a plain list (default: pixels where n_1 is non-zero).

    Returns
    -------
    dict guide -> (H, W, 3) float32 unit directions ℓ_1; background keeps ``light_dir``.
    """
    return _align_components([light_dir], normals, components, gamma, view, ior, mask, None)[0]


def _align_components(
    light_dirs: Sequence[np.ndarray],
    normals: Sequence[np.ndarray] | NormalPyramid,
    components: Mapping[str, Sequence[float]],
    gamma: float,
    view: np.ndarray | None,
    ior: float,
    mask: np.ndarray | None,
    views: dict[int, SoA] | None,
) -> list[dict[str, F32]]:
    """:func:`align_components` of each of ``light_dirs``, in one pass over each level's strips
    (the fields and the view read and upsampled once for all of them); ``views``: a cache of
    the view at the pyramid's coarse levels (see ``_Inputs.view_planes``) shared by calls with
    the same view and pyramid, or None."""
    gamma = LLA_GAMMA.check(gamma, "gamma")
    ior = IOR.check(ior, "ior")
    pyr = normals if isinstance(normals, NormalPyramid) else None
    fields = None
    if pyr is None:
        assert not isinstance(normals, NormalPyramid)
        fields = [np.asarray(n, np.float32) for n in normals]
    if fields is not None:
        if len(fields) < 2:
            raise ValueError(f"normals must hold at least 2 fields, got {len(fields)}")
        shape = fields[0].shape[:2]
        for f in fields:
            if f.shape != (*shape, 3):
                raise ValueError(f"every normal field must be (H, W, 3) = {(*shape, 3)}")
        scales = len(fields)
    else:
        assert pyr is not None
        shape = pyr.shape
        scales = pyr.scales
    if not components:
        raise ValueError("components must name at least one guide")
    comps = {
        _check_guide(g): _check_sigmas(s, scales, f"sigmas of {g!r}") for g, s in components.items()
    }
    needs_view = any(g != "diffuse" for g in comps)
    view_f: F32 | None = None
    view_c: F32 | None = None
    if needs_view:
        if view is None:
            raise ValueError("view is required by the specular and transmission guides")
        view_a = np.asarray(view, np.float32)
        if view_a.shape == (3,):
            norm = float(np.linalg.norm(view_a))
            if not (math.isfinite(norm) and norm > 1e-12):
                raise ValueError("view must be a finite non-zero vector")
            view_c = (view_a / norm).astype(np.float32)
        elif view_a.shape == (*shape, 3):
            view_f = view_a
        else:
            raise ValueError(f"view must be (3,) or (H, W, 3) = {(*shape, 3)}, got {view_a.shape}")
    lights = [_const_or_field(light_dir, shape) for light_dir in light_dirs]
    if fields is not None:
        if mask is None:
            n1 = fields[0]
            m0 = (
                n1[..., 0] * n1[..., 0] + n1[..., 1] * n1[..., 1] + n1[..., 2] * n1[..., 2]
            ) > 0.25
        else:
            m0 = np.asarray(mask) > 0
            if m0.shape != shape:
                raise ValueError(f"mask must be (H, W) = {shape}, got {m0.shape}")
        inp = _Inputs(
            shape,
            comps,
            math.exp(-gamma),
            ior,
            view_f,
            view_c,
            lights,
            fields=[np.asarray(f, np.float32) for f in fields],
            mask=m0.astype(np.float32),
        )
        return _align_full(inp)
    assert pyr is not None
    return _align_pyramid(
        _Inputs(shape, comps, math.exp(-gamma), ior, view_f, view_c, lights, pyr=pyr, views=views)
    )


def align_light(
    light_dir: np.ndarray,
    normals: Sequence[np.ndarray] | NormalPyramid,
    sigmas: Sequence[float],
    gamma: float = DEFAULT_GAMMA,
    guide: Guide | str = "diffuse",
    view: np.ndarray | None = None,
    ior: float = 1.5,
    mask: np.ndarray | None = None,
) -> F32:
    """Light direction aligned with the shape at every scale (LLA §4-6, Eq. 1).

    ℓ_S = ℓ;  ℓ_i = R(ℓ_{i+1} × g_i, σ_i W_γ(λ1 λ2) ∠(ℓ_{i+1}, g_i)) ℓ_{i+1},  i = S−1 … 1
    (Mestres et al. 2021, Eq. 1 and §5; guides of §6). See the module docstring for the frame,
    the guide g_i and λ1, λ2.

    Parameters
    ----------
    light_dir : (3,) unit direction towards the light, or (H, W, 3) per pixel.
    normals : :class:`~ops.filtering.NormalPyramid` or the list [n_1, …, n_S] of (H, W, 3).
    sigmas : σ_1 … σ_{S−1} in [0, 1], finest first (all 0: the light is unchanged).
    gamma : γ of W_γ (paper: 3).
    guide : "diffuse" (normals), "specular" (reflected view vectors) or "transmission"
        (refracted view vectors, index ``ior``).
    view : (H, W, 3) or (3,) unit directions towards the eye (specular / transmission).
    ior : index of refraction for the transmission guide.
    mask : coverage when ``normals`` is a list (default: n_1 non-zero).

    Returns
    -------
    (H, W, 3) float32 unit aligned directions; background keeps ``light_dir``.
    """
    guide = _check_guide(str(guide))
    return align_components(
        light_dir, normals, {guide: sigmas}, gamma=gamma, view=view, ior=ior, mask=mask
    )[guide]


def align_lights(
    lights: Sequence[Light],
    normals: Sequence[np.ndarray] | NormalPyramid,
    position: np.ndarray | None,
    view: np.ndarray | None,
    components: Mapping[str, Sequence[float]],
    gamma: float = DEFAULT_GAMMA,
    ior: float = 1.5,
    mask: np.ndarray | None = None,
) -> dict[str, list[F32]]:
    """Aligned directions of every light for every shading component (LLA §4-6, Eq. 1).

    Directional lights use their direction; point lights the per-pixel direction towards their
    position from ``position`` (:func:`ops.shading.light_vectors`). The lights are aligned
    :data:`LIGHTS_PER_PASS` at a time in one pass over each level's strips (the fields and the
    view made once for them), each as :func:`align_components` aligns it alone, bit for bit.

    Parameters
    ----------
    lights : :class:`ops.shading.Light` list (camera space).
    normals : :class:`~ops.filtering.NormalPyramid` or [n_1, …, n_S].
    position : (H, W, 3) camera-space positions (used by point lights; None when there are none).
    view : (H, W, 3) or (3,) directions towards the eye (specular / transmission).
    components : guide -> σ_1 … σ_{S−1}, e.g. ``{"diffuse": [...], "specular": [...]}``.
    gamma, ior, mask : as in :func:`align_components`.

    Returns
    -------
    dict guide -> one (H, W, 3) float32 field of unit directions per light, in ``lights`` order.
    """
    views: dict[int, SoA] = {}  # one view, one pyramid: its coarse levels made once
    res: list[dict[str, F32]] = []
    for at in range(0, len(lights), LIGHTS_PER_PASS):
        # (a point light's field per pass: made when its pass comes)
        group = [light_direction(light, position) for light in lights[at : at + LIGHTS_PER_PASS]]
        res += _align_components(group, normals, components, gamma, view, ior, mask, views)
    return {g: [per_light[g] for per_light in res] for g in components}
