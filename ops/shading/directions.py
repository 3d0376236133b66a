"""Shading with per-pixel light directions (the aligned lights of Local Light Alignment)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import ParamSpec

import cv2
import numpy as np

from ops.checks import EXPONENT, FRACTION, IOR, ROUGHNESS, SHININESS
from ops.parallel import run_strips
from ops.shading._kernels import (
    _add_gated,
    _add_terms,
    _terms_rows,
    _transmission_rows,
    int_power,
)
from ops.shading.brdf import _blinn_phong_rows, _ggx, _transmission, half_lambert
from ops.shading.lights import Light, light_irradiance, light_vectors, need_positions
from ops.shading.vectors import _dot_rows, _dots, dot

_P = ParamSpec("_P")

__all__ = [
    "DIFFUSE_MODELS",
    "SPECULAR_MODELS",
    "MadeShading",
    "Shading",
    "shade_directions",
    "shading",
]

# -- shading with per-pixel light directions ----------------------------------------------------

#: Diffuse and specular models of :func:`shade_directions`.
DIFFUSE_MODELS: tuple[str, ...] = ("lambert", "half_lambert")
SPECULAR_MODELS: tuple[str, ...] = ("none", "blinn_phong", "ggx")


def _checked_models(
    diffuse: str,
    specular: str,
    shininess: float,
    transmission_exponent: float,
    f0: float,
    ior: float,
    roughness: float | np.ndarray,
) -> np.ndarray:
    """The models and their parameters of :func:`shade_directions` checked; the roughness as an
    array (a field is clipped to [1e-3, 1])."""
    if diffuse not in DIFFUSE_MODELS:
        raise ValueError(f"diffuse must be one of {', '.join(DIFFUSE_MODELS)}; got {diffuse!r}")
    if specular not in SPECULAR_MODELS:
        raise ValueError(f"specular must be one of {', '.join(SPECULAR_MODELS)}; got {specular!r}")
    SHININESS.check(shininess, "shininess")
    EXPONENT.check(transmission_exponent, "transmission_exponent")
    FRACTION.check(f0, "f0")
    IOR.check(ior, "ior")
    rough = np.asarray(roughness, np.float32)
    if rough.ndim == 0:
        ROUGHNESS.check(rough, "roughness")
    else:
        rough = np.clip(rough, np.float32(1e-3), np.float32(1.0))
    return rough


def _positions(
    position: np.ndarray | None, lights: Sequence[Light], shape: tuple[int, ...]
) -> np.ndarray:
    """``position`` as float32; None, where no light needs it, as a read-only (H, W, 3) view of
    one zero (directional lights never read it; point lights do: ValueError)."""
    if position is not None or any(light.kind != "directional" for light in lights):
        return need_positions(position)
    return np.broadcast_to(np.zeros(3, np.float32), (*shape[:2], 3))


def shading(
    normal: np.ndarray,
    view: np.ndarray,
    position: np.ndarray | None,
    lights: Sequence[Light],
    directions: dict[str, Sequence[np.ndarray]] | None = None,
    *,
    diffuse: str = "lambert",
    specular: str = "blinn_phong",
    shininess: float = 32.0,
    roughness: float | np.ndarray = 0.4,
    f0: float = 0.04,
    transmission: bool = False,
    ior: float = 1.5,
    transmission_exponent: float = 16.0,
) -> Shading:
    """The light of each lobe, Σ_i E_i term(n, ℓ_{c,i}, v), with a light direction per component.

    Deferred shading where component c of light i is lit from its own per-pixel direction
    ℓ_{c,i} (the aligned lights of Local Light Alignment §4-6, one per guide), E_i the light's
    irradiance (inverse-square for point lights):

    * diffuse: Lambert max(n·ℓ, 0) or Valve's half-Lambert ((n·ℓ + 1)/2)² (:func:`half_lambert`);
    * specular: Blinn-Phong (n·h)^s (:func:`blinn_phong`), or Cook-Torrance with GGX, Smith
      masking and Schlick Fresnel (:func:`ggx`, Walter et al. 2007; ``roughness`` a number or a
      per-pixel (H, W) pass, ``f0`` the reflectance at normal incidence, so the lobe's colour is
      white), or none; h uses the specular component's light;
    * transmission (``transmission=True``): max(t·ℓ, 0)^e along the refracted view ray t
      (:func:`transmission`).

    Parameters
    ----------
    normal : (H, W, 3) camera-space unit normals; (0, 0, 0) marks pixels without a surface.
    view : (H, W, 3) or (3,) unit directions towards the eye.
    position : (H, W, 3) camera-space positions (point lights' irradiance and directions); None
        when every light is directional.
    lights : the lights, camera space.
    directions : component ("diffuse", "specular", "transmission") -> one (H, W, 3) unit field
        per light, in ``lights`` order; a component not given is lit from the light itself.
    diffuse, specular : models (:data:`DIFFUSE_MODELS`, :data:`SPECULAR_MODELS`).
    shininess, roughness, f0, ior, transmission_exponent : the models' parameters.

    Returns
    -------
    A :class:`Shading` of lobes ``"diffuse"``, ``"specular"`` (unless ``specular="none"``) and
    ``"transmission"`` (when asked), each an (H, W, 3) float32 light without colour, 0 where the
    normal is 0: made on demand, strip by strip, where every light is directional and the
    models are Lambert or half-Lambert and Blinn-Phong or none (a consumer then reads it from
    the caches, never from full-frame arrays); made at once otherwise.
    :func:`shade_directions` gives the arrays.
    """
    rough = _checked_models(diffuse, specular, shininess, transmission_exponent, f0, ior, roughness)
    normal = np.ascontiguousarray(normal, np.float32)
    if normal.ndim != 3 or normal.shape[2] != 3:
        raise ValueError(f"normal must be (H, W, 3), got shape {normal.shape}")
    shape = normal.shape[:2]
    given = dict(directions or {})
    for comp, fields in given.items():
        if comp not in ("diffuse", "specular", "transmission"):
            raise ValueError(f"unknown component {comp!r} in directions")
        if len(fields) != len(lights):
            raise ValueError(f"directions[{comp!r}] must hold one field per light")
    pos = _positions(position, lights, shape)
    view_a = np.asarray(view, np.float32)
    dirs = {comp: [np.asarray(f, np.float32) for f in given[comp]] for comp in given}
    lobes = ["diffuse"] + (["specular"] if specular != "none" else [])
    lobes += ["transmission"] if transmission else []
    if lights and all(light.kind == "directional" for light in lights):
        if specular in ("blinn_phong", "none"):
            models = (diffuse, specular, shininess, ior, transmission_exponent)
            return _Directional(normal, view_a, lights, dirs, models, lobes)
    out = {lobe: np.empty((*shape, 3), np.float32) for lobe in lobes}
    models_any = (diffuse, specular, shininess, f0, ior, transmission_exponent)
    _shade_any(normal, view_a, pos, lights, dirs, models_any, rough, out)
    return MadeShading(out)


def _as_arrays(make: Callable[_P, Shading]) -> Callable[_P, dict[str, np.ndarray]]:
    """A function making a :class:`Shading` as one giving its arrays (the same arguments)."""

    def arrays(*args: _P.args, **kwargs: _P.kwargs) -> dict[str, np.ndarray]:
        """The lobes of the shading these arguments make, as (H, W, 3) float32 arrays."""
        return make(*args, **kwargs).arrays()

    return arrays


#: :func:`shading`'s lobes as (H, W, 3) float32 arrays, lobe -> light (the same arguments).
shade_directions = _as_arrays(shading)


def _shade_any(
    normal: np.ndarray,
    view_a: np.ndarray,
    pos: np.ndarray,
    lights: Sequence[Light],
    dirs: dict[str, list[np.ndarray]],
    models: tuple[str, str, float, float, float, float],
    rough: np.ndarray,
    out: dict[str, np.ndarray],
) -> None:
    """:func:`shade_directions` for any lights and models, into ``out`` (lobe -> (H, W, 3)):
    the formulas of the BRDF terms on row strips."""
    diffuse, specular, shininess, f0, ior, transmission_exponent = models
    shape = normal.shape[:2]
    transmission = "transmission" in out
    lobes = list(out)

    def strip(r0: int, r1: int) -> None:
        # the same per-pixel formulas as on whole fields, on row strips that stay in the caches,
        # restricted to the columns that hold surfaces (0 elsewhere)
        n_rows = normal[r0:r1]
        covered = dot(n_rows, n_rows) > 0.25
        cols = np.flatnonzero(covered.any(axis=0)) if lights else np.zeros(0, np.int64)
        x0, x1 = (int(cols[0]), int(cols[-1]) + 1) if cols.size else (0, 0)
        for lobe in lobes:
            out[lobe][r0:r1, :x0] = 0.0
            out[lobe][r0:r1, x1:] = 0.0
        if x1 == x0:
            return

        def win(a: np.ndarray) -> np.ndarray:  # a view: cv2 takes row-strided arrays
            return a[r0:r1, x0:x1] if a.ndim >= 2 else a

        n = win(normal)
        mask = covered[:, x0:x1].astype(np.float32)
        p = win(pos) if any(light.kind != "directional" for light in lights) else pos
        v = win(view_a)
        rgh = win(rough)
        nv: np.ndarray | None = None
        for i, light in enumerate(lights):
            point = light.kind != "directional"
            own = light_vectors(light, p) if point else np.asarray(light.vector, np.float32)
            e = light_irradiance(light, p)
            first = i == 0
            l_d = win(dirs["diffuse"][i]) if "diffuse" in dirs else own
            if diffuse == "lambert":
                d_term = _dot_rows(n, l_d)
                cv2.threshold(d_term, 0.0, 0.0, cv2.THRESH_TOZERO, d_term)  # lambert()
            else:
                d_term = half_lambert(n, l_d)
            _put(out["diffuse"][r0:r1, x0:x1], d_term, mask, e, first)
            if specular != "none":
                l_s = win(dirs["specular"][i]) if "specular" in dirs else own
                nl = _dot_rows(n, l_s)
                nv = _dot_rows(n, v) if nv is None else nv
                lv = _dot_rows(l_s, v)
                if lv.ndim == 0:
                    lv = np.full(nl.shape, lv, np.float32)
                if specular == "blinn_phong":
                    s_term = _blinn_phong_rows(nl, nv, lv, shininess)
                else:
                    s_term = _ggx(nl, nv, lv, rgh, f0)
                _put(out["specular"][r0:r1, x0:x1], s_term, mask, e, first)
            if transmission:
                l_t = win(dirs["transmission"][i]) if "transmission" in dirs else own
                t_term = _transmission(*_dots(n, l_t, v), ior, transmission_exponent)
                _put(out["transmission"][r0:r1, x0:x1], t_term, mask, e, first)

    run_strips(shape[0], strip, rows=_SHADE_ROWS)


def _flat_rows(
    a: np.ndarray, shape: tuple[int, int, int], what: str, constant: bool = False
) -> tuple[np.ndarray, bool]:
    """An (H, W, 3) field as (H, 3W) float32 rows for a kernel (RGB indexed flat), or with
    ``constant`` a (3,) vector as one (1, 3W) row used for every row; and whether it is that
    one row."""
    a = np.asarray(a, np.float32)
    hgt, wid = shape[:2]
    if constant and a.shape == (3,):
        return np.tile(a, wid).reshape(1, 3 * wid), True
    if a.shape != shape:
        allowed = f"(3,) or {shape}" if constant else f"{shape}"
        raise ValueError(f"{what} must have shape {allowed}, got {a.shape}")
    return np.ascontiguousarray(a).reshape(hgt, 3 * wid), False


#: A field as rows for a kernel and whether it is one row used for all (:func:`_flat_rows`).
_Rows = tuple[np.ndarray, bool]


class Shading(ABC):
    """Each lobe's light of :func:`shade_directions` (lobe -> (H, W, 3) float32), to be read
    as flat rows of a strip (:meth:`rows`) or as whole arrays (:meth:`arrays`)."""

    lobes: list[str]
    shape: tuple[int, int]

    @abstractmethod
    def rows(self, r0: int, r1: int) -> dict[str, np.ndarray]:
        """Rows r0:r1 of each lobe as (r1 − r0, 3W) float32: views of arrays already made, or
        made now (thread-safe: strips may be made on several threads at once)."""

    @abstractmethod
    def arrays(self) -> dict[str, np.ndarray]:
        """Each lobe's light as an (H, W, 3) float32 array."""


class MadeShading(Shading):
    """A shading made already: lobe -> (H, W, 3) float32 arrays."""

    def __init__(self, made: dict[str, np.ndarray], what: str = "shading") -> None:
        self.lobes = list(made)
        if not made:
            raise ValueError(f"{what} needs at least one lobe")
        first = np.shape(made[self.lobes[0]])
        if len(first) != 3:
            raise ValueError(f"{what}[{self.lobes[0]!r}] must be (H, W, 3), got shape {first}")
        self.shape = (int(first[0]), int(first[1]))
        self._made = made
        self._flat = {
            lobe: _flat_rows(a, (*self.shape, 3), f"{what}[{lobe!r}]")[0]
            for lobe, a in made.items()
        }

    def rows(self, r0: int, r1: int) -> dict[str, np.ndarray]:
        return {lobe: flat[r0:r1] for lobe, flat in self._flat.items()}

    def arrays(self) -> dict[str, np.ndarray]:
        return self._made


class _Directional(Shading):
    """:func:`shade_directions` for directional lights, Lambert or half-Lambert, Blinn-Phong or
    no specular, and transmission where ``lobes`` has it (``models``: diffuse, specular,
    shininess, ior, transmission exponent), made strip by strip: per light, one compiled pass
    for the terms (:func:`_terms_rows`, :func:`_transmission_rows`), and one pass raising them to
    the lobe's exponent (a whole one; others with cv2.pow on the strip) and adding them times
    the irradiance. Every pixel's numbers are the same whatever the strips."""

    def __init__(
        self,
        normal: np.ndarray,
        view: np.ndarray,
        lights: Sequence[Light],
        dirs: dict[str, list[np.ndarray]],
        models: tuple[str, str, float, float, float],
        lobes: list[str],
    ) -> None:
        diffuse, specular, shininess, ior, exponent = models
        hgt, wid = normal.shape[:2]
        self.lobes = lobes
        self.shape = (hgt, wid)
        shape = (hgt, wid, 3)
        self._nrm = normal.reshape(hgt, 3 * wid)
        self._view = _flat_rows(view, shape, "view", constant=True)

        def field(comp: str, i: int, own: np.ndarray) -> _Rows:
            given = dirs[comp][i] if comp in dirs else own
            return _flat_rows(given, shape, f"directions[{comp!r}][{i}]", constant=True)

        self._lights: list[tuple[_Rows, _Rows, _Rows, np.ndarray]] = []
        for i, light in enumerate(lights):
            own = np.asarray(light.vector, np.float32)
            e = np.asarray(light_irradiance(light, np.zeros(3, np.float32)), np.float32)
            ld, ls = field("diffuse", i, own), field("specular", i, own)
            lt = field("transmission", i, own) if "transmission" in lobes else ld  # (not read)
            self._lights.append((ld, ls, lt, e.reshape(3)))
        self._spec = specular != "none"
        self._half = diffuse != "lambert"
        self._powers = (float(shininess), float(exponent))
        # whole exponents are raised in the kernels that use them (cv2.pow's products), others
        # by cv2.pow on the strip
        self._whole = (int_power(shininess), int_power(exponent))
        self._eta = np.float32(1.0 / ior)

    def rows(self, r0: int, r1: int) -> dict[str, np.ndarray]:
        out = {lobe: np.empty((r1 - r0, 3 * self.shape[1]), np.float32) for lobe in self.lobes}
        self._into(r0, r1, out)
        return out

    def _into(self, r0: int, r1: int, out: dict[str, np.ndarray]) -> None:
        """Rows r0:r1 of each lobe into ``out`` (lobe -> (r1 − r0, 3W) float32 rows)."""
        wid = self.shape[1]
        n = r1 - r0
        d_term = np.empty((n, wid), np.float32)
        nh = np.empty((n, wid), np.float32)
        gate = np.empty((n, wid), np.float32)
        spec, (shininess, exponent), (s_pow, t_pow) = self._spec, self._powers, self._whole
        od = out["diffuse"]
        os_ = out["specular"] if spec else od[:0]
        ot = out.get("transmission")
        nrm = self._nrm[r0:r1]
        v, vc = self._view
        v_rows = _rows_of((v, vc), r0, r1)
        for i, (ld, ls, lt, e) in enumerate(self._lights):
            d_rows, s_rows = _rows_of(ld, r0, r1), _rows_of(ls, r0, r1)
            args = (d_rows, ld[1], s_rows, ls[1], v_rows, vc, self._half, spec, d_term, nh, gate)
            _terms_rows(nrm, *args)
            if spec and not s_pow:
                cv2.pow(nh, shininess, dst=nh)
            _add_terms(d_term, nh, gate, e, i == 0, spec, s_pow, od, os_)
            if ot is not None:  # (nh and gate are free again)
                lt_rows = _rows_of(lt, r0, r1)
                _transmission_rows(nrm, lt_rows, lt[1], v_rows, vc, self._eta, nh, gate)
                if not t_pow:
                    cv2.pow(nh, exponent, dst=nh)
                _add_gated(nh, gate, e, i == 0, t_pow, ot)

    def arrays(self) -> dict[str, np.ndarray]:
        hgt, wid = self.shape
        made = {lobe: np.empty((hgt, wid, 3), np.float32) for lobe in self.lobes}
        flat = {lobe: a.reshape(hgt, 3 * wid) for lobe, a in made.items()}
        run_strips(
            hgt,
            lambda r0, r1: self._into(r0, r1, {k: f[r0:r1] for k, f in flat.items()}),
            _SHADE_ROWS,
        )
        return made


def _rows_of(a: _Rows, r0: int, r1: int) -> np.ndarray:
    """Rows r0:r1 of a field's flat rows, or its one row used for all."""
    return a[0] if a[1] else a[0][r0:r1]


#: Rows per strip of :func:`shade_directions`.
_SHADE_ROWS = 48


def _put(
    acc: np.ndarray, term: np.ndarray, mask: np.ndarray, irradiance: np.ndarray, first: bool
) -> None:
    """acc (=, or += unless ``first``) term × mask × irradiance; irradiance (3,) or (h, w, 3)."""
    term = np.multiply(term, mask, out=term if term.dtype == np.float32 else None)
    if irradiance.ndim == 1:  # cv2.merge of scaled planes: ~15x faster than cv2.transform 1->3
        planes = [term * c for c in irradiance]
        if first:
            cv2.merge(planes, acc)
        else:
            acc += cv2.merge(planes)
    elif first:
        np.multiply(term[..., None], irradiance, out=acc)
    else:
        acc += term[..., None] * irradiance
