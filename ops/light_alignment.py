"""Local Light Alignment (Mestres et al., "Local Light Alignment for Multi-Scale Shape Depiction",
EG 2021, §4-6).

At each pixel the light direction ℓ is rotated, scale by scale from the coarsest to the finest,
towards a guiding vector g so that one side of every feature faces the light and the other side
is grazed by it. With the multi-scale fields a_1 (finest) … a_S (coarsest) — the normals n_i for
the diffuse component, the reflected view vectors r_i = reflect(v, n_i) for the specular one and
the refracted view vectors t_i = refract(v, n_i, ior) for transmission (§6) — scale i uses the
local frame (§5)::

    z_i = a_{i+1},   x_i = normalize(a_i − z_i (a_i·z_i)),   y_i = x_i × z_i

and (§4, Eq. 1)::

    g_i = a_i                    if ℓ̄_{i+1}·x_i ≥ 0   (the lit side: face the light)
          R(y_i, −π/2) a_i       otherwise            (the other side: the tangent of the
                                                       (x_i, z_i) plane perpendicular to a_i)
    ℓ_i = R(ℓ_{i+1} × g_i, θ_i) ℓ_{i+1},   θ_i = σ_i W_γ(λ1 λ2) ∠(ℓ_{i+1}, g_i)
    W_γ(λ) = λ / (e^{−γ}(1 − λ) + λ),   λ1 = 1 − 2∠(ℓ̄, ḡ)/π,   λ2 = |ā_i|

where v̄ is the projection of v on the (x_i, y_i) plane, ℓ_S = ℓ, and the output ℓ_1.

Notes on the exact geometry (the paper's figures fix what the text leaves open):

- The tangent on the unlit side is t = (z − (a·z) a)/|ā|, the unit vector perpendicular to a in
  the (x, z) plane on the side of z (above the base). It is the tangent that the light reaches by
  turning away from a: rotating ℓ towards it lowers a·ℓ monotonically to 0, whereas the opposite
  tangent would swing the light through a (brightening the dark side first). The paper's
  "R(y, −π/2)" names this rotation in its figure's orientation (y = x × z makes (x, y, z)
  left-handed).
- ℓ̄·x has the sign of a·ℓ − (a·z)(z·ℓ); ḡ is along +x on the lit side and −x on the other, so
  ∠(ℓ̄, ḡ) = atan2(|ℓ·y|, |ℓ·x|) and λ1 = (2/π) atan2(|ℓ·x|, |ℓ·y|) ∈ [0, 1] (0 where ℓ̄ = 0:
  the light along the base normal has no side to turn to).
- λ2 = |ā| = sin ∠(a_i, a_{i+1}) measures how much the feature protrudes from its base.
- Mirror symmetry: a configuration symmetric about a plane containing the light (the ridge of
  Fig. 2 lit exactly along its bisector) stays symmetric — both sides are treated alike. A
  light off the bisector by more than the base normals lean makes one side bright and the
  other dark, as in Fig. 2 b-c.

``σ_i`` is given per scale, finest first: ``sigmas[0]`` rotates towards a_1 within the frame of
a_2 (the paper's Figs. 7, 9, 10 list σ_1 … σ_{S−1} in this order). Background pixels keep the
original light; the output directions are unit length.

Speed: given a :class:`ops.filtering.NormalPyramid`, each scale is aligned at the pyramid level
its fine field lives on (coarse scales are smooth) and the light is carried to finer levels by
the pyramid's edge-aware upsampling; only the scales of the full-resolution field n_1 run at
full resolution. Every level runs the same way (:class:`_Stage`): row strips (restricted to the
columns that hold surfaces) on all cores, where the coarser fields and lights are upsampled
(all planes of a level in one resize) into reused structure-of-arrays scratch buffers and Eq. 1
is one pass-lean chain of cv2 / NumPy calls (:func:`_rotate`); background pixels get the
original light back by a masked copy, not by blending. Given a plain list of (H, W, 3) fields,
every scale runs at full resolution (the reference path).

Rounding: √(1 − (a_i·z)²) amplifies the last bits of nearly parallel fields, and λ1 has no limit
where ℓ̄ → 0 (the light along the frame's z, e.g. at a highlight's centre), so a few pixels of a
frame move by up to ~1e-2 under any change of float32 rounding (a 1e-7 rad turn of the input
light does the same); the fields entering a_i·z are therefore normalised with fixed rounding.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import cv2
import numpy as np

from ops.filtering import F32, NormalPyramid, normalize_field
from ops.parallel import run_strips
from ops.shading import Light, light_vectors

Guide = Literal["diffuse", "specular", "transmission"]
GUIDES: tuple[str, ...] = ("diffuse", "specular", "transmission")
DEFAULT_GAMMA = 3.0

SoA = tuple[F32, F32, F32]
_TWO_OVER_PI = 2.0 / math.pi


def w_gamma(lam: np.ndarray | float, gamma: float = DEFAULT_GAMMA) -> np.ndarray:
    """Confidence weighting W_γ(λ) = λ / (e^{−γ}(1 − λ) + λ) (Mestres et al. 2021, §4).

    Maps [0, 1] onto [0, 1] monotonically with W(0) = 0 and W(1) = 1; W_0 is the identity and a
    larger γ narrows the transition between the bright and the dark side of features.

    Parameters
    ----------
    lam : confidence λ = λ1 λ2 in [0, 1] (array or scalar; clipped to [0, 1]).
    gamma : γ ≥ 0 (the paper uses 3).
    """
    gamma = _check_gamma(gamma)
    lam_a = np.clip(np.asarray(lam, np.float32), 0.0, 1.0)
    e = np.float32(math.exp(-gamma))
    return np.asarray(lam_a / (e + lam_a * (np.float32(1.0) - e)), np.float32)


def _check_gamma(gamma: float) -> float:
    if not (isinstance(gamma, int | float) and math.isfinite(gamma) and 0.0 <= gamma <= 50.0):
        raise ValueError(f"gamma must be in [0, 50], got {gamma!r}")
    return float(gamma)


def _check_sigmas(sigmas: Sequence[float], scales: int, name: str = "sigmas") -> list[float]:
    vals = [float(s) for s in sigmas]
    if len(vals) != scales - 1:
        raise ValueError(
            f"{name} must have one value per scale transition: {scales - 1} for {scales} "
            f"normal fields, got {len(vals)}"
        )
    for s in vals:
        if not (math.isfinite(s) and 0.0 <= s <= 1.0):
            raise ValueError(f"{name} values must be in [0, 1], got {s!r}")
    return vals


def _check_guide(guide: str) -> str:
    if guide not in GUIDES:
        raise ValueError(f"guide must be one of {', '.join(GUIDES)}; got {guide!r}")
    return guide


def _check_ior(ior: float) -> float:
    if not (isinstance(ior, int | float) and math.isfinite(ior) and 0.0 < ior <= 10.0):
        raise ValueError(f"ior must be in (0, 10], got {ior!r}")
    return float(ior)


def _soa(arr: np.ndarray) -> SoA:
    return (
        np.ascontiguousarray(arr[..., 0]),
        np.ascontiguousarray(arr[..., 1]),
        np.ascontiguousarray(arr[..., 2]),
    )


class _Work:
    """Scratch buffers for strips of one shape, reused between calls (one set per thread).

    Temporaries of ~100 KB-1 MB would otherwise be fresh allocations (page faults) at every op.
    Buffers are flat and grow as needed; each call hands out a contiguous view of the current
    strip shape (:meth:`get` sets it), so strips of any width share the same memory.
    """

    _local = threading.local()

    def __init__(self, shape: tuple[int, int]) -> None:
        self._flat: dict[str, np.ndarray] = {}
        self._views: dict[str, F32] = {}
        self.shape = (0, 0)
        self.reshape(shape)

    def reshape(self, shape: tuple[int, int]) -> None:
        if shape == self.shape:
            return
        self.shape = shape
        self._views.clear()
        self.zeros = self._view("#zeros", np.float32, 0.0)
        self.tiny = self._view("#tiny", np.float32, 1e-12)
        self.small = self._view("#small", np.float32, 1e-6)
        self.ones = self._view("#ones", np.float32, 1.0)
        self.boolean = self._view("#bool", np.bool_, None)

    def _view(self, name: str, dtype: type, fill: float | None) -> np.ndarray:
        """A view of buffer ``name``; ``fill``: a constant, written once (never overwritten)."""
        n = self.shape[0] * self.shape[1]
        flat = self._flat.get(name)
        if flat is None or flat.size < n:
            flat = self._flat[name] = np.empty(max(n, 1), dtype)
            if fill is not None:
                flat.fill(fill)
        return flat[:n].reshape(self.shape)

    def __call__(self, name: str) -> F32:
        view = self._views.get(name)
        if view is None:
            view = self._views[name] = self._view(name, np.float32, None)
        return view

    def vec(self, name: str) -> SoA:
        return (self(name + ".x"), self(name + ".y"), self(name + ".z"))

    def arr(self, name: str, shape: tuple[int, ...]) -> F32:
        """A contiguous scratch array of any shape."""
        n = int(np.prod(shape))
        flat = self._flat.get("@" + name)
        if flat is None or flat.size < n:
            flat = self._flat["@" + name] = np.empty(max(n, 1), np.float32)
        return flat[:n].reshape(shape)

    @classmethod
    def get(cls, shape: tuple[int, int]) -> _Work:
        """This thread's workspace, set to strips of ``shape``."""
        work: _Work | None = getattr(cls._local, "work", None)
        if work is None:
            work = cls._local.work = cls(shape)
        work.reshape(shape)
        return work


def _dot(a: SoA, b: SoA, out: F32, tmp: F32 | None = None) -> F32:
    """out = a·b per pixel (``cv2.accumulateProduct`` fuses the multiply-adds)."""
    np.multiply(a[0], b[0], out=out)
    cv2.accumulateProduct(a[1], b[1], out)
    cv2.accumulateProduct(a[2], b[2], out)
    return out


def _normalize_soa(v: SoA, ws: _Work) -> SoA:
    """v / |v| in place, zero vectors (background) stay 0; the same rounding as every field
    of the reference path (the frame's z = a_{i+1} enters √(1 − (a_i·z)²), which amplifies
    the last bits of nearly parallel fields)."""
    n2 = _dot(v, v, ws("n2"))
    np.maximum(n2, ws.tiny, out=n2)
    cv2.sqrt(n2, n2)
    np.divide(_ONE, n2, out=n2)
    for comp in v:
        comp *= n2
    return v


def _normalize_fast(v: SoA, ws: _Work) -> SoA:
    """v / |v| in place, |v| by two ``cv2.magnitude`` calls; zero vectors stay 0. For the
    lights, whose rounding is not amplified."""
    norm = ws("norm")
    cv2.magnitude(v[0], v[1], norm)
    cv2.magnitude(norm, v[2], norm)
    np.maximum(norm, ws.tiny, out=norm)
    for comp in v:
        cv2.divide(comp, norm, comp)
    return v


def _pos(x: F32) -> F32:
    """max(x, 0) in place (``cv2.threshold``: ~5x faster than ``np.maximum`` with a scalar)."""
    cv2.threshold(x, 0.0, 0.0, cv2.THRESH_TOZERO, x)
    return x


_ONE = np.float32(1.0)


def _rotate(a: SoA, b: SoA, light: SoA, sigma: float, egam: float, out: SoA, ws: _Work) -> SoA:
    """One scale of Eq. 1 (Mestres et al. 2021, §4-5) on structure-of-arrays fields.

    a = a_i (fine), b = a_{i+1} (coarse, the frame's z), light = ℓ_{i+1} (unit vectors); writes
    ℓ_i (unit) into ``out`` (which must not alias the inputs). Every pixel is rotated: callers
    put the original light back on background pixels.

    With c = a·z, the side test p = |ā| (ℓ·x) = a·ℓ − c (z·ℓ), |ā| = √(1 − c²) = λ2 and
    q = |ā| |ℓ·y| = √(|ā|² (1 − (z·ℓ)²) − p²): λ1 = (2/π) atan2(|p|, q); g = a where p > 0
    (at p = 0, λ1 = 0 and θ = 0), else the tangent t = (z − c a)/|ā|; Ω = ∠(ℓ, g) and the
    rotation is the slerp ℓ_i ∝ sin(Ω − θ) ℓ + sin θ g with θ = σ W_γ(λ1 λ2) Ω.
    """
    t = ws("t1")
    c = _dot(a, b, ws("c"))  # a·z
    al = _dot(a, light, ws("al"))  # a·ℓ
    bl = _dot(b, light, ws("bl"))  # z·ℓ
    p = ws("p")  # |ā| (ℓ·x): the side test
    np.multiply(c, bl, out=p)
    np.subtract(al, p, out=p)
    s = ws("s")  # |ā|² = 1 − (a·z)²
    np.multiply(c, c, out=s)
    np.subtract(_ONE, s, out=s)
    _pos(s)
    q = ws("q")  # |ā| |ℓ·y| = sqrt(|ā|² (1 − (z·ℓ)²) − p²)
    np.multiply(bl, bl, out=q)
    np.subtract(_ONE, q, out=q)
    q *= s
    np.multiply(p, p, out=t)
    q -= t
    cv2.sqrt(_pos(q), q)
    cv2.sqrt(s, s)  # λ2 = |ā|
    np.abs(p, out=t)
    lam = ws("lam")  # λ1 π/2 = atan2(|ℓ·x|, |ℓ·y|), then λ = λ1 λ2
    cv2.phase(q, t, lam)
    cv2.multiply(lam, s, lam, scale=_TWO_OVER_PI)
    k = ws("k")  # σ W_γ(λ) = σ λ / (e^{−γ} + λ (1 − e^{−γ}))
    cv2.addWeighted(lam, 1.0 - egam, lam, 0.0, egam, t)
    cv2.divide(lam, t, k, scale=sigma)
    lit, isd = ws("lit"), ws("isd")  # 1 on the lit side (ℓ̄·x > 0), else 0
    cv2.threshold(p, 0.0, 1.0, cv2.THRESH_BINARY, lit)
    np.maximum(s, ws.tiny, out=isd)  # 1/|ā| on the other side, 0 on the lit side
    np.subtract(_ONE, lit, out=t)
    np.divide(t, isd, out=isd)
    gl = ws("gl")  # g·ℓ: a·ℓ (lit) or t·ℓ = (z·ℓ − c a·ℓ)/|ā|
    np.multiply(c, al, out=gl)
    np.subtract(bl, gl, out=gl)
    gl *= isd
    cv2.accumulateProduct(al, lit, gl)
    np.clip(gl, -1.0, 1.0, out=gl)
    sin_o = ws("sin_o")  # sin Ω
    np.multiply(gl, gl, out=sin_o)
    np.subtract(_ONE, sin_o, out=sin_o)
    cv2.sqrt(_pos(sin_o), sin_o)
    theta = ws("theta")  # θ = σ W_γ Ω
    cv2.phase(gl, sin_o, theta)
    theta *= k
    cos_t, sin_t = ws("cos"), ws("sin")
    cv2.polarToCart(ws.ones, theta, cos_t, sin_t)
    # sin(Ω − θ) = sin Ω cos θ − cos Ω sin θ, with sin Ω ≥ 1e-6 (where ℓ and g coincide)
    np.maximum(sin_o, ws.small, out=sin_o)
    coef_a = cos_t
    coef_a *= sin_o
    np.multiply(gl, sin_t, out=t)
    coef_a -= t
    # g = h a + isd z, h = 1 (lit) or −c/|ā| (other side)
    ca = ws("ca")
    np.multiply(c, isd, out=ca)
    np.subtract(lit, ca, out=ca)
    ca *= sin_t
    cb = isd
    cb *= sin_t
    for o, lc, acomp, bcomp in zip(out, light, a, b, strict=True):
        np.multiply(coef_a, lc, out=o)
        cv2.accumulateProduct(ca, acomp, o)
        cv2.accumulateProduct(cb, bcomp, o)
    return _normalize_fast(out, ws)


def _guide_soa(guide: str, n: SoA, view: SoA | None, ior: float, out: SoA, ws: _Work) -> SoA:
    """a_i for a guide (§6) on structure-of-arrays strips: n_i (diffuse), the reflected view
    vector (specular) or the refracted view vector (transmission) — the formulas of
    :func:`ops.shading.reflect` / :func:`ops.shading.refract` (the tests hold them equal),
    written into scratch buffers instead of new (H, W, 3) arrays.

    specular: r = 2 (n·v) n − v;  transmission: t = −η v + (η cos_i − √k) n, η = 1/ior,
    cos_i = n·v, k = 1 − η² (1 − cos_i²), t = 0 where k < 0.
    """
    if guide == "diffuse":
        return n
    assert view is not None
    t1 = ws("g1")
    cos_i = _dot(n, view, ws("g0"), t1)
    if guide == "specular":
        for o, nc, vc in zip(out, n, view, strict=True):
            cv2.multiply(cos_i, nc, o, scale=2.0)  # (n·v) n × 2: exact, as 2 (n·v) × n
            o -= vc
        return out
    eta = np.float32(1.0 / ior)
    k = ws("g2")
    np.multiply(cos_i, cos_i, out=k)
    np.subtract(np.float32(1.0), k, out=k)
    k *= np.float32(-eta * eta)
    k += np.float32(1.0)
    ok = ws("g3")
    np.greater_equal(k, ws.zeros, out=ws.boolean)
    np.copyto(ok, ws.boolean)
    np.maximum(k, ws.zeros, out=k)
    cv2.sqrt(k, k)
    cos_i *= eta
    cos_i -= k  # η cos_i − √k
    for o, nc, vc in zip(out, n, view, strict=True):
        np.multiply(cos_i, nc, out=o)
        np.multiply(vc, eta, out=t1)
        o -= t1
        o *= ok
    return out


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
    gamma : γ of W_γ, ≥ 0.
    view : (H, W, 3) or (3,) unit directions towards the eye (needed by "specular" and
        "transmission").
    ior : index of refraction of the transmission guide, in (0, 10].
    mask : (H, W) coverage for a plain list (default: pixels where n_1 is non-zero).

    Returns
    -------
    dict guide -> (H, W, 3) float32 unit directions ℓ_1; background keeps ``light_dir``.
    """
    gamma = _check_gamma(gamma)
    ior = _check_ior(ior)
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
    const, lfield = _const_or_field(light_dir, shape)
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
            const,
            lfield,
            fields=[np.asarray(f, np.float32) for f in fields],
            mask=m0.astype(np.float32),
        )
        return _align_full(inp)
    assert pyr is not None
    inp = _Inputs(shape, comps, math.exp(-gamma), ior, view_f, view_c, const, lfield, pyr=pyr)
    return _align_pyramid(inp)


def _fill(vec: SoA, value: np.ndarray) -> SoA:
    for comp, val in zip(vec, value, strict=True):
        comp.fill(float(val))
    return vec


def _copy_in(vec: SoA, arr: np.ndarray) -> SoA:
    """Interleaved (h, w, 3) rows into structure-of-arrays buffers (``cv2.split`` into
    preallocated planes: ~5x faster than strided NumPy copies)."""
    if arr.dtype != np.float32 or arr.strides[1:] != (12, 4):
        arr = np.ascontiguousarray(arr, np.float32)
    cv2.split(arr, list(vec))  # rows may be strided (a column window)
    return vec


def _window(v: SoA, win: Win) -> SoA:
    r0, r1, x0, x1 = win
    return (v[0][r0:r1, x0:x1], v[1][r0:r1, x0:x1], v[2][r0:r1, x0:x1])


Win = tuple[int, int, int, int]  # rows r0:r1, columns x0:x1 (at the stage's level)
State = tuple[int, SoA]  # a component's light aligned so far: (level, planes, 0 on background)

# Rows per strip, and at least this many pixels per strip (coarse levels are narrow): each call
# then works long enough for the two threads to overlap rather than wait on each other.
_ROWS = 64
_STRIP_PIXELS = 1 << 15


def _strip_rows(width: int) -> int:
    return max(_ROWS, -(-_STRIP_PIXELS // max(1, width)))


class _Inputs:
    """What every stage of one :func:`align_components` call shares."""

    def __init__(
        self,
        shape: tuple[int, int],
        comps: dict[str, list[float]],
        egam: float,
        ior: float,
        view: F32 | None,
        view_const: F32 | None,
        const: F32 | None,
        lfield: F32 | None,
        pyr: NormalPyramid | None = None,
        fields: list[F32] | None = None,
        mask: F32 | None = None,
    ) -> None:
        self.shape = shape
        self.comps = comps
        self.egam = egam
        self.ior = ior
        self.view = view
        self.view_const = view_const
        self.const = const
        self.lfield = lfield
        self.pyr = pyr
        self.fields = fields
        if pyr is not None:
            self.masks = pyr.geometry.mask
            self.back8 = pyr.geometry.mask_u8(background=True)
        else:
            assert mask is not None
            self.masks = [mask]
            self.back8 = np.asarray(mask <= 0).view(np.uint8)
        self._views: dict[int, SoA] = {}
        self._lights: dict[int, SoA] = {}
        self.rows: F32 | None = None
        if const is not None:  # a strip of the constant light (level-0 rows are copied from it)
            self.rows = np.empty((min(shape[0], _strip_rows(shape[1])), shape[1], 3), np.float32)
            self.rows[:] = np.tile(const, (shape[1], 1))
        self.outs = {g: np.empty((*shape, 3), np.float32) for g in comps}

    def needs_view(self, comps: Sequence[str]) -> bool:
        return any(g != "diffuse" for g in comps)

    def view_planes(self, k: int) -> SoA:
        """The view at level k > 0 (the field is smooth: plain area averaging, each level from
        the finest one already made), renormalised, as planes (cached)."""
        got = self._views.get(k)
        if got is None:
            assert self.view is not None and self.pyr is not None
            hk, wk = self.pyr.geometry.shape(k)
            src = max((lv for lv in self._views if lv < k), default=0)
            base = self.view if src == 0 else cv2.merge(list(self._views[src]))
            small = cv2.resize(base, (wk, hk), interpolation=cv2.INTER_AREA)
            got = self._views[k] = _soa(normalize_field(small))
        return got

    def light_planes(self, k: int) -> SoA:
        """The original (per-pixel) light at level k > 0, 0 on background (cached)."""
        got = self._lights.get(k)
        if got is None:
            assert self.lfield is not None and self.pyr is not None
            got = self._lights[k] = _soa(self.pyr.geometry.down(self.lfield, 0, k))
        return got


class _Stage:
    """The scales aligned at one pyramid level k, strip by strip, on the columns that hold
    surfaces: per strip the fields (those of coarser levels upsampled edge-aware and
    renormalised), the view and the incoming light of each component become
    structure-of-arrays buffers, and Eq. 1 is applied from the coarsest scale of the level to
    the finest. At level 0 the result is written to the outputs, whose other pixels (background,
    components left unchanged) keep the original light; at coarser levels it becomes the
    components' new states (0 on background)."""

    def __init__(
        self, inp: _Inputs, k: int, steps: list[int], states: dict[str, State | None]
    ) -> None:
        self.inp = inp
        self.k = k
        self.steps = sorted(steps, reverse=True)
        self.states = states
        comps = inp.comps
        active = [g for g, sig in comps.items() if any(sig[j] > 0.0 for j in steps)]
        if k == 0:
            active = [g for g in comps if g in active or states.get(g) is not None]
        self.active = active
        self.mask = inp.masks[k]
        self.shape = (int(self.mask.shape[0]), int(self.mask.shape[1]))
        self.new: dict[str, SoA] = {}
        if k > 0:
            for g in active:
                self.new[g] = (
                    np.zeros(self.shape, np.float32),
                    np.zeros(self.shape, np.float32),
                    np.zeros(self.shape, np.float32),
                )
        # what comes from coarser levels: the fields z = a_{j+1} and the lights aligned so far
        by_level: dict[int, list[tuple[str, SoA]]] = {}
        pyr = inp.pyr
        if pyr is not None:
            for j in steps:
                if pyr.levels[j + 1] > k and any(comps[g][j] > 0.0 for g in active):
                    by_level.setdefault(pyr.levels[j + 1], []).append(
                        (f"n{j + 1}", pyr.planes(j + 1))
                    )
            for g in active:
                state = states.get(g)
                if state is not None:
                    by_level.setdefault(state[0], []).append((f"light:{g}", state[1]))
        self.sources: list[tuple[int, list[str], list[F32], tuple[Any, Any, Any]]] = []
        for lvl, items in sorted(by_level.items()):
            planes = [plane for _, vec in items for plane in vec]
            assert pyr is not None
            sparse = pyr.geometry.up_sparse(planes, lvl, k)
            self.sources.append((lvl, [n for n, _ in items], planes, sparse))
        self.with_view = inp.needs_view(active)

    # -- inputs of a strip ------------------------------------------------------------------

    def upsample(self, win: Win, ws: _Work) -> dict[str, SoA]:
        r0, r1, x0, x1 = win
        ups: dict[str, SoA] = {}
        if not self.sources:
            return ups
        assert self.inp.pyr is not None
        geo = self.inp.pyr.geometry
        for lvl, names, planes_k, sparse in self.sources:
            planes = geo.up_rows(
                planes_k, lvl, (r0, r1), ws.arr, sparse, k_to=self.k, cols=(x0, x1)
            )
            for i, name in enumerate(names):
                vec = (planes[3 * i], planes[3 * i + 1], planes[3 * i + 2])
                # bilinear shortens unit vectors (to 0 … 1 next to background): renormalise
                norm = _normalize_fast if name.startswith("light:") else _normalize_soa
                ups[name] = norm(vec, ws)
        return ups

    def field(self, i: int, win: Win, ws: _Work, ups: dict[str, SoA]) -> SoA:
        r0, r1, x0, x1 = win
        inp = self.inp
        if inp.fields is not None:
            return _copy_in(ws.vec(f"n{i}"), inp.fields[i][r0:r1, x0:x1])
        assert inp.pyr is not None
        lvl = inp.pyr.levels[i]
        if lvl > self.k:
            return ups[f"n{i}"]
        if self.k == 0:
            return _copy_in(ws.vec(f"n{i}"), inp.pyr.normals[i][r0:r1, x0:x1])
        return _window(inp.pyr.planes(i), win)

    def view(self, win: Win, ws: _Work) -> SoA:
        r0, r1, x0, x1 = win
        inp = self.inp
        if inp.view is None:
            assert inp.view_const is not None
            return _fill(ws.vec("view"), inp.view_const)
        if self.k == 0:
            return _copy_in(ws.vec("view"), inp.view[r0:r1, x0:x1])
        return _window(inp.view_planes(self.k), win)

    def light(self, g: str, win: Win, ws: _Work, ups: dict[str, SoA]) -> SoA:
        if self.states.get(g) is not None:
            return ups[f"light:{g}"]
        r0, r1, x0, x1 = win
        inp = self.inp
        if inp.lfield is None:
            assert inp.const is not None
            return _fill(ws.vec("light_in"), inp.const)
        if self.k == 0:
            return _copy_in(ws.vec("light_in"), inp.lfield[r0:r1, x0:x1])
        return _window(inp.light_planes(self.k), win)

    # -- a strip ------------------------------------------------------------------------------

    def fill(self, out: F32, r0: int, r1: int, x0: int, x1: int) -> None:
        """Level 0: the original light on rows r0:r1, columns x0:x1 of an output."""
        inp = self.inp
        if x1 <= x0:
            return
        if inp.lfield is not None:
            np.copyto(out[r0:r1, x0:x1], inp.lfield[r0:r1, x0:x1])
        else:  # from rows of the light (a (3,) broadcast over (h, w, 3) is ~10x slower)
            assert inp.rows is not None
            out[r0:r1, x0:x1] = inp.rows[: r1 - r0, x0:x1]

    def strip(self, r0: int, r1: int) -> None:
        k = self.k
        inp = self.inp
        width = self.shape[1]
        cols = np.flatnonzero(self.mask[r0:r1].max(axis=0)) if self.active else np.zeros(0, int)
        if not cols.size:
            if k == 0:  # all background, or no component changes
                for dst in inp.outs.values():
                    self.fill(dst, r0, r1, 0, width)
            return
        # window width rounded up (a few scratch-buffer shapes serve every strip)
        x0 = int(cols[0])
        step = 128 if k == 0 else 16
        wd = min(width, -(-(int(cols[-1]) + 1 - x0) // step) * step)
        x0 = min(x0, width - wd)
        win = (r0, r1, x0, x0 + wd)
        if k == 0:  # the original light outside the window (inside it: :meth:`write`)
            for g, dst in inp.outs.items():
                if g in self.active:
                    self.fill(dst, r0, r1, 0, x0)
                    self.fill(dst, r0, r1, x0 + wd, width)
                else:
                    self.fill(dst, r0, r1, 0, width)
        ws = _Work.get((r1 - r0, wd))
        ups = self.upsample(win, ws)
        view = self.view(win, ws) if self.with_view else None
        fields: dict[int, SoA] = {}
        for g in self.active:
            light = self.light(g, win, ws, ups)
            ping = 0
            for j in self.steps:
                sig = inp.comps[g][j]
                if sig <= 0.0:
                    continue
                for i in (j, j + 1):
                    if i not in fields:
                        fields[i] = self.field(i, win, ws, ups)
                a = _guide_soa(g, fields[j], view, inp.ior, ws.vec("ga"), ws)
                b = _guide_soa(g, fields[j + 1], view, inp.ior, ws.vec("gb"), ws)
                out = ws.vec(f"light{ping}")
                light = _rotate(a, b, light, sig, inp.egam, out, ws)
                ping = 1 - ping
            self.write(g, light, win, ws)

    def write(self, g: str, light: SoA, win: Win, ws: _Work) -> None:
        r0, r1, x0, x1 = win
        inp = self.inp
        if self.k == 0:  # the window, then its background pixels back to the original light
            out = inp.outs[g][r0:r1, x0:x1]
            cv2.merge(list(light), out)
            orig = inp.lfield if inp.lfield is not None else inp.rows
            assert orig is not None
            r_o = (r0, r1) if inp.lfield is not None else (0, r1 - r0)
            cv2.copyTo(orig[r_o[0] : r_o[1], x0:x1], inp.back8[r0:r1, x0:x1], out)
            return
        mrows = self.mask[r0:r1, x0:x1]
        for comp, dst in zip(light, self.new[g], strict=True):
            np.multiply(comp, mrows, out=dst[r0:r1, x0:x1])

    def run(self) -> None:
        rows = _strip_rows(self.shape[1])
        run_strips(self.shape[0], self.strip, rows=rows)
        for g, planes in self.new.items():
            self.states[g] = (self.k, planes)


def _align_full(inp: _Inputs) -> dict[str, F32]:
    """Every scale at full resolution, strip by strip."""
    assert inp.fields is not None
    _Stage(inp, 0, list(range(len(inp.fields) - 1)), {}).run()
    return inp.outs


def _align_pyramid(inp: _Inputs) -> dict[str, F32]:
    """Each scale at the level of its fine field, coarsest first, and the lights carried to
    finer levels by the pyramid's edge-aware upsampling; level 0 writes the outputs."""
    pyr = inp.pyr
    assert pyr is not None
    active = [j for j in range(pyr.scales - 1) if any(sig[j] > 0.0 for sig in inp.comps.values())]
    states: dict[str, State | None] = {g: None for g in inp.comps}
    for k in sorted({pyr.levels[j] for j in active} | {0}, reverse=True):
        if k > 0 and inp.needs_view(list(inp.comps)):
            for lv in sorted({pyr.levels[j] for j in active if 0 < pyr.levels[j] <= k}):
                if inp.view is not None:
                    inp.view_planes(lv)  # finest first: each from the previous
        _Stage(inp, k, [j for j in active if pyr.levels[j] == k], states).run()
    return inp.outs


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
    position: np.ndarray,
    view: np.ndarray | None,
    components: Mapping[str, Sequence[float]],
    gamma: float = DEFAULT_GAMMA,
    ior: float = 1.5,
    mask: np.ndarray | None = None,
) -> dict[str, list[F32]]:
    """Aligned directions of every light for every shading component (LLA §4-6, Eq. 1).

    Directional lights use their direction; point lights the per-pixel direction towards their
    position from ``position`` (:func:`ops.shading.light_vectors`).

    Parameters
    ----------
    lights : :class:`ops.shading.Light` list (camera space).
    normals : :class:`~ops.filtering.NormalPyramid` or [n_1, …, n_S].
    position : (H, W, 3) camera-space positions (used by point lights).
    view : (H, W, 3) or (3,) directions towards the eye (specular / transmission).
    components : guide -> σ_1 … σ_{S−1}, e.g. ``{"diffuse": [...], "specular": [...]}``.
    gamma, ior, mask : as in :func:`align_components`.

    Returns
    -------
    dict guide -> one (H, W, 3) float32 field of unit directions per light, in ``lights`` order.
    """
    out: dict[str, list[F32]] = {g: [] for g in components}
    for light in lights:
        if light.kind == "directional":
            ldir: np.ndarray = np.asarray(light.vector, np.float32)
        else:
            ldir = light_vectors(light, np.asarray(position, np.float32))
        res = align_components(
            ldir, normals, components, gamma=gamma, view=view, ior=ior, mask=mask
        )
        for g in components:
            out[g].append(res[g])
    return out
