"""Shading with per-pixel light directions (the aligned lights of Local Light Alignment)."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from ops.checks import EXPONENT, FRACTION, IOR, ROUGHNESS, SHININESS
from ops.parallel import run_strips
from ops.shading._kernels import _add_gated, _add_terms, _terms_rows, _transmission_rows
from ops.shading.brdf import _blinn_phong_rows, _ggx, _transmission, half_lambert
from ops.shading.lights import Light, light_irradiance, light_vectors, need_positions
from ops.shading.vectors import _dot_rows, _dots, dot

__all__ = ["DIFFUSE_MODELS", "SPECULAR_MODELS", "shade_directions"]

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


def shade_directions(
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
) -> dict[str, np.ndarray]:
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
    dict lobe -> (H, W, 3) float32 light without colour: ``"diffuse"``, ``"specular"`` (unless
    ``specular="none"``) and ``"transmission"`` (when asked); 0 where the normal is 0.
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
    out = {lobe: np.empty((*shape, 3), np.float32) for lobe in lobes}
    if all(light.kind == "directional" for light in lights) and lights:
        if specular in ("blinn_phong", "none"):
            models = (diffuse, specular, shininess, ior, transmission_exponent)
            _shade_directional(normal, view_a, lights, dirs, models, out)
            return out

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
    return out


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


def _shade_directional(
    normal: np.ndarray,
    view: np.ndarray,
    lights: Sequence[Light],
    dirs: dict[str, list[np.ndarray]],
    models: tuple[str, str, float, float, float],
    out: dict[str, np.ndarray],
) -> None:
    """:func:`shade_directions` for directional lights, Lambert or half-Lambert, Blinn-Phong or
    no specular, and transmission where ``out`` has that lobe (``models``: diffuse, specular,
    shininess, ior, transmission exponent): per light, one compiled pass per strip for the terms
    (:func:`_terms_rows`, :func:`_transmission_rows`), the powers with cv2.pow on the strip, and
    one pass adding them times the irradiance."""
    diffuse, specular, shininess, ior, exponent = models
    hgt, wid = normal.shape[:2]
    shape = (hgt, wid, 3)
    nrm = normal.reshape(hgt, 3 * wid)
    v, vc = _flat_rows(view, shape, "view", constant=True)

    def field(comp: str, i: int, own: np.ndarray) -> _Rows:
        given = dirs[comp][i] if comp in dirs else own
        return _flat_rows(given, shape, f"directions[{comp!r}][{i}]", constant=True)

    per_light: list[tuple[_Rows, _Rows, _Rows, np.ndarray]] = []
    for i, light in enumerate(lights):
        own = np.asarray(light.vector, np.float32)
        e = np.asarray(light_irradiance(light, np.zeros(3, np.float32)), np.float32)
        ld, ls = field("diffuse", i, own), field("specular", i, own)
        lt = field("transmission", i, own) if "transmission" in out else ld  # (not read)
        per_light.append((ld, ls, lt, e.reshape(3)))
    spec = specular != "none"
    half = diffuse != "lambert"
    od = out["diffuse"].reshape(hgt, 3 * wid)
    os_ = out["specular"].reshape(hgt, 3 * wid) if spec else od[:0]
    ot = out["transmission"].reshape(hgt, 3 * wid) if "transmission" in out else None
    eta = np.float32(1.0 / ior)

    def rows(a: _Rows, r0: int, r1: int) -> np.ndarray:
        return a[0] if a[1] else a[0][r0:r1]

    def strip(r0: int, r1: int) -> None:
        n = r1 - r0
        d_term = np.empty((n, wid), np.float32)
        nh = np.empty((n, wid), np.float32)
        gate = np.empty((n, wid), np.float32)
        for i, (ld, ls, lt, e) in enumerate(per_light):
            d_rows, s_rows, v_rows = rows(ld, r0, r1), rows(ls, r0, r1), rows((v, vc), r0, r1)
            args = (d_rows, ld[1], s_rows, ls[1], v_rows, vc, half, spec, d_term, nh, gate)
            _terms_rows(nrm[r0:r1], *args)
            if spec:
                cv2.pow(nh, float(shininess), dst=nh)
            _add_terms(d_term, nh, gate, e, i == 0, spec, od[r0:r1], os_[r0:r1] if spec else os_)
            if ot is not None:  # (nh and gate are free again)
                _transmission_rows(nrm[r0:r1], rows(lt, r0, r1), lt[1], v_rows, vc, eta, nh, gate)
                cv2.pow(nh, float(exponent), dst=nh)
                _add_gated(nh, gate, e, i == 0, ot[r0:r1])

    run_strips(hgt, strip, rows=_SHADE_ROWS)


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
