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
full resolution, as structure-of-arrays strips of 32 rows (restricted to the columns that hold
surfaces) in reused scratch buffers, on all cores. Given a plain list of (H, W, 3) fields, every
scale runs at full resolution (the reference path).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import cv2
import numpy as np

from ops.filtering import F32, NormalPyramid, normalize_field, run_strips
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
        self.fields: dict[str, SoA] = {}  # per-strip inputs (this thread's strip)
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
        self.boolean = self._view("#bool", np.bool_, None)

    def _view(self, name: str, dtype: type, fill: float | None) -> np.ndarray:
        n = self.shape[0] * self.shape[1]
        flat = self._flat.get(name)
        if flat is None or flat.size < n:
            flat = self._flat[name] = np.empty(max(n, 1), dtype)
        view = flat[:n].reshape(self.shape)
        if fill is not None:
            view.fill(fill)
        return view

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


def _dot(a: SoA, b: SoA, out: F32, tmp: F32) -> F32:
    """out = a·b per pixel (``cv2.accumulateProduct`` fuses the multiply-adds)."""
    np.multiply(a[0], b[0], out=out)
    cv2.accumulateProduct(a[1], b[1], out)
    cv2.accumulateProduct(a[2], b[2], out)
    return out


def _normalize_soa(v: SoA, ws: _Work) -> SoA:
    n2 = _dot(v, v, ws("n2"), ws("n2t"))
    np.maximum(n2, ws.tiny, out=n2)
    cv2.sqrt(n2, n2)
    np.divide(np.float32(1.0), n2, out=n2)
    for comp in v:
        comp *= n2
    return v


def _rotate(
    a: SoA, b: SoA, light: SoA, sigma: float, egam: float, mask: F32, out: SoA, ws: _Work
) -> SoA:
    """One scale of Eq. 1 (Mestres et al. 2021, §4-5) on structure-of-arrays fields.

    a = a_i (fine), b = a_{i+1} (coarse, the frame's z), light = ℓ_{i+1}; writes ℓ_i (unit)
    into ``out`` (which must not alias the inputs). ``mask`` (float 0/1) zeroes θ on background
    pixels so that they keep their light.
    """
    t1 = ws("t1")
    zeros = ws.zeros
    c = _dot(a, b, ws("c"), t1)  # a·z
    al = _dot(a, light, ws("al"), t1)  # a·ℓ
    bl = _dot(b, light, ws("bl"), t1)  # z·ℓ
    p = ws("p")  # |ā| (ℓ·x): the side test
    np.multiply(c, bl, out=p)
    np.subtract(al, p, out=p)
    s = ws("s")  # λ2 = |ā| = sqrt(1 − (a·z)²)
    np.multiply(c, c, out=s)
    np.subtract(np.float32(1.0), s, out=s)
    np.maximum(s, zeros, out=s)
    q = ws("q")  # |ā| |ℓ·y| = sqrt(|ā|² (1 − (z·ℓ)²) − p²)
    np.multiply(bl, bl, out=q)
    np.subtract(np.float32(1.0), q, out=q)
    q *= s
    np.multiply(p, p, out=t1)
    q -= t1
    np.maximum(q, zeros, out=q)
    cv2.sqrt(q, q)
    cv2.sqrt(s, s)
    np.abs(p, out=t1)
    lam = ws("lam")  # λ1 π/2 = atan2(|ℓ·x|, |ℓ·y|), then λ = λ1 λ2
    cv2.phase(q, t1, lam)
    cv2.multiply(lam, s, lam, scale=_TWO_OVER_PI)
    wgt = ws("w")  # W_γ(λ) = λ / (e^{−γ} + λ (1 − e^{−γ}))
    cv2.addWeighted(lam, 1.0 - egam, lam, 0.0, egam, t1)
    np.divide(lam, t1, out=wgt)
    bright = ws("bright")  # 1 on the lit side (ℓ̄·x ≥ 0), else 0
    np.greater_equal(p, zeros, out=ws.boolean)
    np.copyto(bright, ws.boolean)
    inv_s = ws("inv_s")
    np.maximum(s, ws.tiny, out=inv_s)
    np.divide(np.float32(1.0), inv_s, out=inv_s)
    gl = ws("gl")  # g·ℓ: lit side a·ℓ, other side t·ℓ with t = (z − (a·z) a)/|ā|
    np.multiply(c, al, out=gl)
    np.subtract(bl, gl, out=gl)
    gl *= inv_s
    np.subtract(al, gl, out=t1)
    t1 *= bright
    gl += t1
    np.clip(gl, -1.0, 1.0, out=gl)
    sin_o = ws("sin_o")
    np.multiply(gl, gl, out=sin_o)
    np.subtract(np.float32(1.0), sin_o, out=sin_o)
    np.maximum(sin_o, zeros, out=sin_o)
    cv2.sqrt(sin_o, sin_o)
    theta = ws("theta")  # θ = σ W_γ ∠(ℓ, g), 0 on background
    cv2.phase(gl, sin_o, theta)
    cv2.multiply(theta, wgt, theta, scale=sigma)
    theta *= mask
    cos_t, sin_t = ws("cos"), ws("sin")
    cv2.polarToCart(None, theta, cos_t, sin_t)  # type: ignore[call-overload]
    # slerp: ℓ' = cosθ ℓ + sinθ (g − (g·ℓ) ℓ)/sinΩ = A ℓ + B g, B = sinθ / sinΩ
    coef_b = sin_t
    np.maximum(sin_o, ws.small, out=t1)
    coef_b /= t1
    coef_a = cos_t
    np.multiply(coef_b, gl, out=t1)
    coef_a -= t1
    # g = a (lit) or (b − c a)/|ā| (other): ℓ' = A ℓ + Ca a + Cb b
    cb = ws("cb")
    np.multiply(coef_b, inv_s, out=cb)
    ca = ws("ca")
    np.multiply(cb, c, out=ca)
    np.negative(ca, out=ca)
    np.subtract(coef_b, ca, out=t1)
    t1 *= bright
    ca += t1  # lit: B, other: −B c/|ā|
    np.multiply(cb, bright, out=t1)
    cb -= t1  # lit: 0, other: B/|ā|
    for o, lc, acomp, bcomp in zip(out, light, a, b, strict=True):
        np.multiply(coef_a, lc, out=o)
        cv2.accumulateProduct(ca, acomp, o)
        cv2.accumulateProduct(cb, bcomp, o)
    return _normalize_soa(out, ws)


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
        cos_i *= np.float32(2.0)
        for o, nc, vc in zip(out, n, view, strict=True):
            np.multiply(cos_i, nc, out=o)
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
        m0f = m0.astype(np.float32)
        return _align_full(fields, m0f, comps, gamma, view_f, view_c, ior, const, lfield)
    assert pyr is not None
    return _align_pyramid(pyr, comps, gamma, view_f, view_c, ior, const, lfield)


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


Win = tuple[int, int, int, int]  # rows r0:r1, columns x0:x1


class _Level0:
    """The full-resolution scales, strip by strip: per strip (restricted to the columns that
    hold surface pixels) the fields of each scale, the view and the incoming light of each
    component are made into structure-of-arrays buffers, and Eq. 1 is applied from the
    coarsest level-0 scale to the finest. Pixels outside the windows are background and keep
    the original light."""

    def __init__(
        self,
        shape: tuple[int, int],
        mask: F32,
        steps: list[int],
        comps: dict[str, list[float]],
        egam: float,
        ior: float,
        view: F32 | None,
        view_const: F32 | None,
        const: F32 | None,
        lfield: F32 | None,
    ) -> None:
        self.shape = shape
        self.mask = mask
        self.steps = sorted(steps, reverse=True)
        self.comps = comps
        self.egam = egam
        self.ior = ior
        self.view = view
        self.view_const = view_const
        self.const = const
        self.lfield = lfield
        self.outs = {g: np.empty((*shape, 3), np.float32) for g in comps}

    def field(self, i: int, win: Win, ws: _Work) -> SoA:  # pragma: no cover - abstract
        raise NotImplementedError

    def light(self, g: str, win: Win, ws: _Work) -> SoA:  # pragma: no cover - abstract
        raise NotImplementedError

    def prepare(self, win: Win, ws: _Work) -> None:
        """Per-strip inputs shared by the components (the upsampled coarse fields)."""

    def orig_light(self, win: Win, ws: _Work) -> SoA:
        r0, r1, x0, x1 = win
        if self.lfield is not None:
            return _copy_in(ws.vec("light_in"), self.lfield[r0:r1, x0:x1])
        assert self.const is not None
        return _fill(ws.vec("light_in"), self.const)

    def strip(self, r0: int, r1: int) -> None:
        cols = np.flatnonzero(self.mask[r0:r1].max(axis=0))
        if not cols.size:
            return  # all background: the original light, already in place
        width = self.shape[1]
        # window width rounded up (a few scratch-buffer shapes serve every strip)
        x0 = int(cols[0])
        wd = min(width, -(-(int(cols[-1]) + 1 - x0) // 128) * 128)
        x0 = min(x0, width - wd)
        win = (r0, r1, x0, x0 + wd)
        ws = _Work.get((r1 - r0, wd))
        mrows = self.mask[r0:r1, x0 : x0 + wd]
        self.prepare(win, ws)
        view: SoA | None = None
        if any(g != "diffuse" for g in self.comps):
            if self.view is not None:
                view = _copy_in(ws.vec("view"), self.view[r0:r1, x0 : x0 + wd])
            else:
                assert self.view_const is not None
                view = _fill(ws.vec("view"), self.view_const)
        fields: dict[int, SoA] = {}
        for g in self.comps:
            light = self.light(g, win, ws)
            ping = 0
            for j in self.steps:
                sig = self.comps[g][j]
                if sig <= 0.0:
                    continue
                for i in (j, j + 1):
                    if i not in fields:
                        fields[i] = self.field(i, win, ws)
                a = _guide_soa(g, fields[j], view, self.ior, ws.vec("ga"), ws)
                b = _guide_soa(g, fields[j + 1], view, self.ior, ws.vec("gb"), ws)
                out = ws.vec(f"light{ping}")
                light = _rotate(a, b, light, sig, self.egam, mrows, out, ws)
                ping = 1 - ping
            light = self.finish(g, light, win, ws)
            cv2.merge(list(light), self.outs[g][r0:r1, x0 : x0 + wd])

    def finish(self, g: str, light: SoA, win: Win, ws: _Work) -> SoA:
        """Last touch on a component's strip before it is written."""
        return light

    def run(self) -> dict[str, F32]:
        for out in self.outs.values():  # background everywhere, surfaces overwritten
            if self.lfield is not None:
                np.copyto(out, self.lfield)
            else:  # one row, then rows (a (3,) broadcast over (H, W, 3) is ~10x slower)
                out[:] = np.tile(np.asarray(self.const, np.float32), (self.shape[1], 1))
        run_strips(self.shape[0], self.strip)
        return self.outs


class _Level0Fields(_Level0):
    """Every field given at full resolution (a plain list of normals)."""

    def __init__(self, fields: list[F32], **kw: Any) -> None:
        super().__init__(**kw)
        self.fields = fields

    def field(self, i: int, win: Win, ws: _Work) -> SoA:
        r0, r1, x0, x1 = win
        return _copy_in(ws.vec(f"n{i}"), self.fields[i][r0:r1, x0:x1])

    def light(self, g: str, win: Win, ws: _Work) -> SoA:
        return self.orig_light(win, ws)


class _Level0Pyramid(_Level0):
    """Fields of coarser levels and the lights aligned at coarse scales are brought to full
    resolution strip by strip (:meth:`ops.filtering.DepthPyramid.up_rows`, into cache-sized
    scratch buffers), renormalised, and background pixels get the original light back."""

    def __init__(
        self, pyr: NormalPyramid, states: dict[str, tuple[int, SoA | None]], **kw: Any
    ) -> None:
        super().__init__(**kw)
        self.pyr = pyr
        self.states = states
        needed = {j + 1 for j in self.steps if any(sig[j] > 0 for sig in self.comps.values())}
        by_level: dict[int, list[tuple[str, SoA]]] = {}
        for i in sorted(needed):
            if pyr.levels[i] > 0:
                by_level.setdefault(pyr.levels[i], []).append((f"n{i}", pyr.planes(i)))
        for g, (lvl, cur) in states.items():
            if cur is not None:
                by_level.setdefault(lvl, []).append((f"light:{g}", cur))
        geo = pyr.geometry
        # per source level: the names, the fields as planes, the sparse joint bilateral pixels
        self.sources: list[tuple[int, list[str], list[F32], tuple[Any, Any, Any]]] = []
        for lvl, items in by_level.items():
            planes = [plane for _, vec in items for plane in vec]
            self.sources.append((lvl, [n for n, _ in items], planes, geo.up_sparse(planes, lvl)))

    def prepare(self, win: Win, ws: _Work) -> None:
        r0, r1, x0, x1 = win
        geo = self.pyr.geometry
        ups: dict[str, SoA] = {}
        for lvl, names, planes_k, sparse in self.sources:
            planes = geo.up_rows(planes_k, lvl, (r0, r1), ws.arr, sparse, cols=(x0, x1))
            for i, name in enumerate(names):
                vec = (planes[3 * i], planes[3 * i + 1], planes[3 * i + 2])
                # bilinear shortens unit vectors (to 0 … 1 next to background): renormalise
                ups[name] = _normalize_soa(vec, ws)
        ws.fields = ups

    def finish(self, g: str, light: SoA, win: Win, ws: _Work) -> SoA:
        """Background keeps the original light: ℓ = ℓ0 + m (ℓ − ℓ0)."""
        if self.states[g][1] is None:
            return light
        r0, r1, x0, x1 = win
        mrows = self.mask[r0:r1, x0:x1]
        orig: Sequence[float | F32]
        if self.lfield is None:
            assert self.const is not None
            orig = [float(c) for c in self.const]
        else:
            orig = _copy_in(ws.vec("orig"), self.lfield[r0:r1, x0:x1])
        for comp, o in zip(light, orig, strict=True):
            comp -= o
            comp *= mrows
            comp += o
        return light

    def field(self, i: int, win: Win, ws: _Work) -> SoA:
        r0, r1, x0, x1 = win
        if self.pyr.levels[i] == 0:
            return _copy_in(ws.vec(f"n{i}"), self.pyr.normals[i][r0:r1, x0:x1])
        return ws.fields[f"n{i}"]

    def light(self, g: str, win: Win, ws: _Work) -> SoA:
        if self.states[g][1] is None:
            return self.orig_light(win, ws)
        return ws.fields[f"light:{g}"]


def _align_full(
    fields: list[F32],
    m0: F32,
    comps: dict[str, list[float]],
    gamma: float,
    view: F32 | None,
    view_const: F32 | None,
    ior: float,
    const: F32 | None,
    lfield: F32 | None,
) -> dict[str, F32]:
    """Every scale at full resolution, strip by strip."""
    stage = _Level0Fields(
        fields,
        const=const,
        lfield=lfield,
        shape=m0.shape,
        mask=m0,
        steps=list(range(len(fields) - 1)),
        comps=comps,
        egam=math.exp(-gamma),
        ior=ior,
        view=view,
        view_const=view_const,
    )
    return stage.run()


def _align_pyramid(
    pyr: NormalPyramid,
    comps: dict[str, list[float]],
    gamma: float,
    view: F32 | None,
    view_const: F32 | None,
    ior: float,
    const: F32 | None,
    lfield: F32 | None,
) -> dict[str, F32]:
    """Coarse scales at their pyramid levels, the level-0 scales in full-resolution strips."""
    geo = pyr.geometry
    egam = math.exp(-gamma)
    levels = pyr.levels
    views: dict[int, F32] = {}

    def view_at(k: int) -> F32:
        # the view field is smooth (it does not depend on depth): plain area averaging, each
        # level from the next finer one already made
        if k not in views:
            hk, wk = geo.shape(k)
            if view is None:
                assert view_const is not None
                arr = np.empty((hk, wk, 3), np.float32)
                arr[...] = view_const
                views[k] = arr
            else:
                src = max((lv for lv in views if lv < k), default=0)
                base = view if src == 0 else views[src]
                small = cv2.resize(base, (wk, hk), interpolation=cv2.INTER_AREA)
                views[k] = normalize_field(small)
        return views[k]

    def orig_light_at(k: int) -> SoA:
        hk, wk = geo.shape(k)
        if lfield is None:
            assert const is not None
            return tuple(np.full((hk, wk), float(c), np.float32) for c in const)  # type: ignore[return-value]
        return _soa(geo.down(lfield, 0, k))

    def zero_background(vec: SoA, m_k: F32) -> SoA:
        for comp in vec:
            comp *= m_k
        return vec

    # coarse scales (fine field above level 0), coarsest first; the states are 0 on background
    states: dict[str, tuple[int, SoA | None]] = {g: (0, None) for g in comps}
    n_steps = pyr.scales - 1
    needed = [j for j in range(n_steps) if levels[j] > 0 and any(s[j] > 0 for s in comps.values())]
    for k in sorted({levels[j] for j in needed}):  # finest first: each from the previous
        if any(g != "diffuse" for g in comps):
            view_at(k)

    def alloc(name: str, shape: tuple[int, ...]) -> F32:
        return np.empty(shape, np.float32)

    for j in sorted(needed, reverse=True):
        k = levels[j]
        active = [g for g, sig in comps.items() if sig[j] > 0.0]
        hk, wk = geo.shape(k)
        ws = _Work((hk, wk))
        m_k = geo.mask[k]
        # what comes from coarser levels: z = n_{j+1} and the lights aligned so far
        sources: dict[int, list[tuple[str, SoA]]] = {}
        if levels[j + 1] > k:
            sources.setdefault(levels[j + 1], []).append(("z", pyr.planes(j + 1)))
        lights: dict[str, SoA] = {}
        for g in active:
            lvl, cur = states[g]
            if cur is None:
                lights[g] = zero_background(orig_light_at(k), m_k)
            elif lvl == k:
                lights[g] = cur
            else:
                sources.setdefault(lvl, []).append((g, cur))
        ups: dict[str, SoA] = {}
        for lvl, items in sources.items():
            planes_k = [plane for _, vec in items for plane in vec]
            sparse = geo.up_sparse(planes_k, lvl, k_to=k)
            planes = geo.up_rows(planes_k, lvl, (0, hk), alloc, sparse, k_to=k)
            for i, (name, _) in enumerate(items):
                vec = (planes[3 * i], planes[3 * i + 1], planes[3 * i + 2])
                ups[name] = _normalize_soa(vec, ws)
        lights.update({g: ups[g] for g in active if g in ups})
        a_n = pyr.planes(j)
        b_n = ups["z"] if "z" in ups else pyr.planes(j + 1)
        vk = _soa(view_at(k)) if any(g != "diffuse" for g in active) else None
        for g in active:
            a = _guide_soa(g, a_n, vk, ior, ws.vec("ga"), ws)
            b = _guide_soa(g, b_n, vk, ior, ws.vec("gb"), ws)
            out = (np.empty((hk, wk), np.float32) for _ in range(3))
            new = _rotate(a, b, lights[g], comps[g][j], egam, m_k, tuple(out), ws)  # type: ignore[arg-type]
            states[g] = (k, zero_background(new, m_k))

    stage = _Level0Pyramid(
        pyr,
        states,
        const=const,
        lfield=lfield,
        shape=pyr.shape,
        mask=geo.mask[0],
        steps=[j for j in range(n_steps) if levels[j] == 0],
        comps=comps,
        egam=egam,
        ior=ior,
        view=view,
        view_const=view_const,
    )
    return stage.run()


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
