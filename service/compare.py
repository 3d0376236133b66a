"""The comparison bench of Local Light Alignment (Mestres et al., EG 2021, §7, Figs. 12-14).

:func:`compare` shades one frame's geometry with each depiction method under the fixed sweep of
light directions of :func:`ops.directions.comparison_directions` and scores every rendering with
the congruence score of :func:`ops.congruence.congruence` (LLA Eq. 2) against the frame's depth.
:func:`plot` draws the scores like the paper's Fig. 13, :func:`contact_sheet` lays out the
renderings with their per-pixel score maps like Fig. 12, and :func:`score_frame` scores a frame's
own beauty (``depict score``).

Methods (all but Exaggerated Shading shade with Lambert, as in LLA §7, Fig. 13):

``lambert``
    ρ max(n·ℓ, 0) (Fig. 14 a; :func:`ops.baselines.lambert_image`).
``radiance_scaling``
    Radiance Scaling (Vergne et al., TVCG 2011, Eq. 2 and §5.1) of that Lambert term with the
    settings of LLA Fig. 14 e: isotropic curvature (λ = 0), α = 0.5, γ = 4;
    I = σ_{α,γ}(κ, δ) δ with δ = max(n·ℓ, 0) (the diffuse reflectance term, RS §5.1) and
    κ = tanh(s (κ1 + κ2)) (:func:`ops.curvature.isotropic`).
``exaggerated_shading``
    Exaggerated Shading (Rusinkiewicz, Burns, DeCarlo 2006) with its own clamped half-Lambertian
    (Fig. 14 c; :func:`ops.baselines.exaggerated_shading`).
``light_warping``
    Our directional-light approximation of Light Warping (Vergne et al. 2009), Lambert shading
    with the warped light (Fig. 14 d; :func:`ops.baselines.light_warping`).
``light_alignment``
    Local Light Alignment, LLA Eq. 1 applied coarse to fine (§5) with the diffuse guide (§4):
    the light aligned per pixel by :func:`ops.light_alignment.align_light` on the depth-guided
    multi-scale normals of :func:`ops.filtering.normal_pyramid` (computed once per frame),
    then Lambert max(n·ℓ', 0) (Fig. 14 b). Defaults follow the paper's recommendations: γ = 3
    ("γ = 3 in all the results presented in the paper", §4), S = 6 scales (§5: "S ∈ {5, 6, 7}
    is mostly enough") with σ_i = (0.5, 0.3, 0.1, 0.2, 0.2), finest first, the "fine-tuned"
    setting of Fig. 7, and the pyramid's own defaults for the filter sizes (σ_1 = 0.005 of the
    image height, × 1.7 per scale, §5).

Directions. The fixed sweep of :mod:`ops.directions`: #1 frontal, then four arcs (light from
the right, above, left, below) at 30°, 60°, 90° (grazing), 120° and 150° (behind) from the view
axis. The paper's inset is not in its text; this sweep follows its description.

Albedo. By default every method shades a **white** surface (ρ = 1). The score compares the
luminance flow of the picture with the shape flow; a texture would add the same shape-unrelated
gradients to every method and blur the differences, and the paper's comparison renderings
(Figs. 12, 14) are untextured. ``albedo="frame"`` multiplies each rendering by the frame's albedo
buffer instead (RGB images).

Display range. Every shading is clipped to [0, 1] before it is scored, as the renderings the
paper compares are displayed pictures (Figs. 12, 14). Only Radiance Scaling is affected: with
γ = 4 its factor σ reaches e^{±γκ} = 55 (δ → 1, κ → 1) and its unclipped output spans two
decades, which would make the score's per-image strength normalisation (a percentile) see
only the blown-out highlights.

Score. Every image is scored with :func:`ops.congruence.congruence` on the frame's depth and
coverage, with the same congruence parameters for all methods (``params["congruence"]``) and
sizes relative to the frame's display height.

Normalisation (``shading_norm``). Eq. 2 compares a shading strength with a shape strength, which
need a common scale; the paper does not say which. By default (``"reference"``) every rendering
of the frame is put on **one** scale: its shading strength is divided by that of the frame's
plain Lambert rendering under direction #1 (its 95th percentile), the same number for every
method and direction. A method that raises shading contrast then keeps it, and the clamp of
Eq. 2 ("prevents the score from dropping in case of exaggeration, i.e. if e_s > e_c", §7) acts
as the paper describes. ``"per_image"`` divides each rendering by its own percentile instead
(as :func:`score_frame` does for a single image, which makes a score invariant to brightness):
then extra contrast is normalised away, and a method that concentrates contrast at features
(Light Alignment) loses to Lambert under near-frontal lights, where their directions agree.
A number pins the scale.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from gbuffer.frame import Frame
from ops.baselines import exaggerated_shading, lambert_image, light_warping
from ops.congruence import CongruenceResult, congruence
from ops.curvature import DEFAULT_SCALE, isotropic, principal_curvatures
from ops.directions import N_DIRECTIONS, comparison_directions
from ops.shading import dot, lambert

F32 = NDArray[np.float32]

#: Methods of the comparison, in the order of the tables and plots.
METHODS: tuple[str, ...] = (
    "lambert",
    "radiance_scaling",
    "exaggerated_shading",
    "light_warping",
    "light_alignment",
)
#: Display names (tables, legends, sheets).
LABELS: dict[str, str] = {
    "lambert": "Lambert",
    "radiance_scaling": "Radiance Scaling",
    "exaggerated_shading": "Exaggerated Shading",
    "light_warping": "Light Warping",
    "light_alignment": "Light Alignment",
}
#: Directions shown by default on a contact sheet, like the rows of LLA Fig. 12 (from well lit
#: to grazing to behind): frontal, 60° and grazing from the right, 150° behind on the right,
#: grazing from above, 150° behind on the left (the paper's numbers differ from our sweep's).
SHEET_DIRECTIONS: tuple[int, ...] = (1, 3, 4, 6, 9, 16)
#: Albedo choices.
ALBEDOS: tuple[str, ...] = ("white", "frame")

#: Curvature gain of the curvature-based methods here: above the operators' default (0.03,
#: chosen for looks), as both score higher with it on the shared meshes (Radiance Scaling 0.515
#: against 0.501, Light Warping 0.621 against 0.557, mean congruence), so neither baseline is
#: weakened by the choice.
COMPARE_CURVATURE_GAIN = 0.1

#: Parameters of each method and of the score, as used when none are given (JSON-able).
DEFAULT_PARAMS: dict[str, dict[str, Any]] = {
    "congruence": {
        "gradient_scale": 0.002,
        "integration_scale": 0.01,
        "percentile": 95.0,
        "shape": "normals",
    },
    "lambert": {},
    "radiance_scaling": {
        "alpha": 0.5,
        "gamma": 4.0,
        "curvature_scale": DEFAULT_SCALE,
        "curvature_gain": COMPARE_CURVATURE_GAIN,
    },
    "exaggerated_shading": {},
    "light_warping": {
        "strength": 1.0,
        "curvature_scale": DEFAULT_SCALE,
        "curvature_gain": COMPARE_CURVATURE_GAIN,
    },
    "light_alignment": {
        "sigmas": [0.5, 0.3, 0.1, 0.2, 0.2],
        "gamma": 3.0,
    },
}
#: Keys of ``params["light_alignment"]`` that configure the multi-scale normals (the rest go to
#: :func:`ops.light_alignment.align_light`).
_PYRAMID_KEYS = ("base", "factor", "depth_sigma")


# -- parameters --------------------------------------------------------------------------------


def resolve_params(params: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, dict]:
    """:data:`DEFAULT_PARAMS` updated with ``params`` (one dict per method, plus
    ``"congruence"``); raises ValueError naming an unknown section."""
    out = {k: dict(v) for k, v in DEFAULT_PARAMS.items()}
    for key, value in (params or {}).items():
        if key not in out:
            allowed = ", ".join(out)
            raise ValueError(f"params: unknown section {key!r}; allowed: {allowed}")
        if not isinstance(value, Mapping):
            raise ValueError(f"params[{key!r}] must be a mapping of parameter names to values")
        out[key].update(value)
    return out


def _check_methods(methods: Iterable[str]) -> tuple[str, ...]:
    ms = tuple(methods)
    if not ms:
        raise ValueError(f"methods must name at least one of: {', '.join(METHODS)}")
    for m in ms:
        if m not in METHODS:
            raise ValueError(f"methods: unknown method {m!r}; allowed: {', '.join(METHODS)}")
    if len(set(ms)) != len(ms):
        raise ValueError(f"methods must not repeat a method, got {list(ms)}")
    return ms


def _call(name: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """Call ``fn``, turning an unknown keyword (TypeError) into a ValueError naming ``name``."""
    try:
        return fn(*args, **kwargs)
    except TypeError as exc:
        raise ValueError(f"params[{name!r}]: {exc}") from None


#: Shape signals of the score: the normals' gradients (planes carry no weight) or the log depth's.
SHAPES = ("normals", "depth")


def score_image(
    image: F32,
    depth: F32,
    mask: NDArray[np.generic],
    normal: F32 | None,
    image_height: int,
    **cong: Any,
) -> CongruenceResult:
    """:func:`ops.congruence.congruence` of ``image`` with the congruence parameters ``cong``,
    whose ``shape`` ("normals", the default, or "depth") picks the shape signal; without
    normals the shape is the depth."""
    shape = cong.pop("shape", "normals")
    if shape not in SHAPES:
        raise ValueError(f"params['congruence']: shape must be one of {SHAPES}, got {shape!r}")
    use = normal if shape == "normals" else None
    return _call(
        "congruence", congruence, image, depth, mask, image_height=image_height, normal=use, **cong
    )


# -- the methods -------------------------------------------------------------------------------


@dataclass
class _Geometry:
    """What every method reads from the frame, plus caches shared across directions."""

    normal: F32
    depth: F32
    mask: NDArray[np.bool_]
    albedo: F32 | None  # (H, W, 3) or None for white
    image_height: int
    params: dict[str, dict[str, Any]]
    _kappa: dict[tuple[float, float], F32] = field(default_factory=dict)
    _pyramid: Any = None

    def kappa(self, scale: float, gain: float) -> F32:
        """Isotropic curvature κ = tanh(s (κ1 + κ2)) (RS §4), cached per (scale, gain)."""
        key = (float(scale), float(gain))
        if key not in self._kappa:
            curv = principal_curvatures(
                self.normal, self.depth, self.mask, scale=scale, image_height=self.image_height
            )
            self._kappa[key] = np.asarray(isotropic(curv, gain), np.float32)
        return self._kappa[key]

    def multiscale(self) -> Any:
        """The :class:`ops.filtering.NormalPyramid` n_1 … n_S of LLA §5, computed once."""
        if self._pyramid is None:
            from ops.filtering import normal_pyramid

            p = self.params["light_alignment"]
            sig = p.get("sigmas", DEFAULT_PARAMS["light_alignment"]["sigmas"])
            scales = len(sig) + 1
            kw = {k: p[k] for k in _PYRAMID_KEYS if k in p}
            self._pyramid = _call(
                "light_alignment",
                normal_pyramid,
                self.normal,
                self.depth,
                self.mask,
                scales=scales,
                **kw,
            )
        return self._pyramid

    def finish(self, shading: F32) -> F32:
        """Shading clipped to [0, 1] (the display range), × albedo (RGB) or white; 0 off
        coverage."""
        img = np.where(self.mask, np.clip(shading, 0.0, 1.0), np.float32(0.0)).astype(np.float32)
        if self.albedo is None:
            return img
        return np.asarray(self.albedo * img[..., None], np.float32)


def _lambert(g: _Geometry, light: F32) -> F32:
    return g.finish(lambert_image(g.normal, g.mask, light))


def _radiance_scaling(g: _Geometry, light: F32) -> F32:
    from ops.scaling import sigma

    p = dict(g.params["radiance_scaling"])
    kappa = g.kappa(
        p.pop("curvature_scale", DEFAULT_SCALE), p.pop("curvature_gain", COMPARE_CURVATURE_GAIN)
    )
    delta = lambert(g.normal, light)
    scale = _call("radiance_scaling", sigma, kappa, delta, **p)
    return g.finish(np.asarray(scale * delta, np.float32))


def _exaggerated(g: _Geometry, light: F32) -> F32:
    p = g.params["exaggerated_shading"]
    img = _call(
        "exaggerated_shading",
        exaggerated_shading,
        g.normal,
        g.depth,
        g.mask,
        light,
        image_height=g.image_height,
        **p,
    )
    return g.finish(img)


def _warping(g: _Geometry, light: F32) -> F32:
    p = dict(g.params["light_warping"])
    kappa = g.kappa(
        p.pop("curvature_scale", DEFAULT_SCALE), p.pop("curvature_gain", COMPARE_CURVATURE_GAIN)
    )
    img = _call(
        "light_warping",
        light_warping,
        g.normal,
        g.depth,
        g.mask,
        light,
        curvature=kappa,
        image_height=g.image_height,
        **p,
    )
    return g.finish(img)


def _alignment(g: _Geometry, light: F32) -> F32:
    from ops.light_alignment import align_light

    p = {k: v for k, v in g.params["light_alignment"].items() if k not in _PYRAMID_KEYS}
    sig = p.pop("sigmas", DEFAULT_PARAMS["light_alignment"]["sigmas"])
    gamma = p.pop("gamma", DEFAULT_PARAMS["light_alignment"]["gamma"])
    normals = g.multiscale()
    aligned = _call(
        "light_alignment", align_light, light, normals, sig, gamma, guide="diffuse", **p
    )
    return g.finish(lambert(g.normal, np.asarray(aligned, np.float32)))


_SHADERS: dict[str, Callable[[_Geometry, F32], F32]] = {
    "lambert": _lambert,
    "radiance_scaling": _radiance_scaling,
    "exaggerated_shading": _exaggerated,
    "light_warping": _warping,
    "light_alignment": _alignment,
}


# -- the result --------------------------------------------------------------------------------


def _direction_angles(d: NDArray[np.floating]) -> tuple[float, float]:
    """(θ to the view axis, azimuth φ) in degrees of a camera-space direction."""
    theta = math.degrees(math.acos(max(-1.0, min(1.0, float(d[2])))))
    phi = math.degrees(math.atan2(float(d[1]), float(d[0]))) % 360.0
    if theta < 1e-6:
        phi = 0.0
    return theta, phi


@dataclass
class ComparisonResult:
    """Scores of each method under each light direction (LLA §7, Fig. 13).

    Attributes
    ----------
    methods : method names, in table order.
    numbers : the N direction numbers (1-based, of the fixed sweep) that were compared.
    directions : (N, 3) float32 light directions, row j is direction #numbers[j].
    scores : (M, N) float64, ``scores[m, j]`` = congruence score of method m under
        #numbers[j].
    results : method -> the N :class:`ops.congruence.CongruenceResult` (their maps on demand).
    images : method -> {direction number (1-based): rendering} for the kept directions.
    params : the resolved parameters (JSON-able).
    albedo : ``"white"`` or ``"frame"``.
    image_shape : (H, W) of the renderings.
    seconds : method -> seconds spent shading (scoring excluded); ``"score"`` -> scoring.
    label : free text naming the input (a mesh or file name).
    shading_norm : ``{"mode": "reference" | "per_image" | "pinned", "value": float | None}``,
        the scale of the shading strengths (see the module docstring).
    """

    methods: tuple[str, ...]
    numbers: tuple[int, ...]
    directions: F32
    scores: NDArray[np.float64]
    results: dict[str, list[CongruenceResult]]
    images: dict[str, dict[int, F32]]
    params: dict[str, dict[str, Any]]
    albedo: str
    image_shape: tuple[int, int]
    seconds: dict[str, float] = field(default_factory=dict)
    label: str = ""
    shading_norm: dict[str, Any] = field(default_factory=lambda: {"mode": "per_image"})

    @property
    def n_directions(self) -> int:
        return int(self.directions.shape[0])

    @property
    def means(self) -> dict[str, float]:
        """Mean score of each method over the directions."""
        return {m: float(self.scores[i].mean()) for i, m in enumerate(self.methods)}

    def score(self, method: str, direction: int) -> float:
        """Score of ``method`` under direction ``#direction`` (1-based)."""
        return float(self.scores[self._row(method), self._col(direction)])

    def score_map(self, method: str, direction: int) -> F32:
        """Per-pixel score map (H, W) of ``method`` under ``#direction``."""
        return self.results[method][self._col(direction)].score_map

    def image(self, method: str, direction: int) -> F32:
        """The rendering of ``method`` under ``#direction`` (if it was kept)."""
        self._row(method)
        self._col(direction)
        try:
            return self.images[method][direction]
        except KeyError:
            kept = sorted(self.images.get(method, {}))
            raise ValueError(
                f"the image of {method} under #{direction} was not kept (kept: {kept}); "
                "pass keep_images=True or the direction numbers to compare()"
            ) from None

    def _row(self, method: str) -> int:
        if method not in self.methods:
            raise ValueError(f"method {method!r} was not compared; compared: {self.methods}")
        return self.methods.index(method)

    def _col(self, direction: int) -> int:
        if not isinstance(direction, int | np.integer) or int(direction) not in self.numbers:
            raise ValueError(
                f"direction must be one of the compared numbers {list(self.numbers)}, "
                f"got {direction!r}"
            )
        return self.numbers.index(int(direction))

    def claims(self, method: str = "light_alignment", baseline: str = "lambert") -> dict:
        """The paper's claim for ``method``: above ``baseline`` at every direction and above every
        other method on average (LLA §7, Fig. 13). Empty when ``method`` was not compared."""
        if method not in self.methods:
            return {}
        row = self.scores[self._row(method)]
        out: dict[str, Any] = {"method": method}
        if baseline in self.methods and baseline != method:
            diff = row - self.scores[self._row(baseline)]
            out["baseline"] = baseline
            out["above_baseline_count"] = int((diff > 0).sum())
            out["above_baseline_everywhere"] = bool((diff > 0).all())
            out["min_margin_over_baseline"] = float(diff.min())
            out["directions_not_above_baseline"] = [
                self.numbers[int(k)] for k in np.nonzero(diff <= 0)[0]
            ]
        means = self.means
        others = {m: v for m, v in means.items() if m != method}
        out["mean"] = means[method]
        out["best_mean"] = bool(all(means[method] > v for v in others.values()))
        out["mean_margin_over_others"] = {m: means[method] - v for m, v in others.items()}
        return out

    # -- tables --------------------------------------------------------------------------------

    def table_markdown(self, digits: int = 3) -> str:
        """Markdown: one row per direction (#, θ, φ, a score per method; the best in bold), a
        row of means, and one line on the claim of LLA §7."""
        head = ["#", "θ°", "φ°", *(LABELS[m] for m in self.methods)]
        lines = ["| " + " | ".join(head) + " |", "|" + "---:|" * len(head)]
        fmt = f"{{:.{digits}f}}"
        for k in range(self.n_directions):
            theta, phi = _direction_angles(self.directions[k])
            col = self.scores[:, k]
            best = float(col.max())
            cells = [
                f"**{fmt.format(v)}**" if v == best and len(col) > 1 else fmt.format(v) for v in col
            ]
            num = self.numbers[k]
            lines.append(f"| {num} | {theta:.0f} | {phi:.0f} | " + " | ".join(cells) + " |")
        means = list(self.means.values())
        best_mean = max(means)
        cells = [
            f"**{fmt.format(v)}**" if v == best_mean and len(means) > 1 else fmt.format(v)
            for v in means
        ]
        lines.append("| mean | | | " + " | ".join(cells) + " |")
        claim = self.claims()
        if claim.get("baseline"):
            lines.append("")
            lines.append(
                f"Light Alignment above Lambert at {claim['above_baseline_count']}/"
                f"{self.n_directions} directions"
                + (
                    f" (not at #{', #'.join(map(str, claim['directions_not_above_baseline']))})"
                    if claim["directions_not_above_baseline"]
                    else ""
                )
                + f"; best mean: {'yes' if claim['best_mean'] else 'no'}."
            )
        mode = self.shading_norm.get("mode")
        scale = {
            "reference": "one scale for every rendering, the frame's Lambert under #1",
            "per_image": "each rendering on its own scale",
            "pinned": f"a pinned scale ({self.shading_norm.get('value')})",
        }
        if mode in scale:
            lines.append(f"Shading strengths: {scale[mode]}.")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able summary: directions, scores per method, means, the claim, parameters."""
        dirs = []
        for k in range(self.n_directions):
            theta, phi = _direction_angles(self.directions[k])
            dirs.append(
                {
                    "index": self.numbers[k],
                    "vector": [round(float(x), 6) for x in self.directions[k]],
                    "theta_deg": round(theta, 3),
                    "phi_deg": round(phi, 3),
                }
            )
        return {
            "label": self.label,
            "image_shape": list(self.image_shape),
            "albedo": self.albedo,
            "methods": list(self.methods),
            "directions": dirs,
            "scores": {m: [float(v) for v in self.scores[i]] for i, m in enumerate(self.methods)},
            "means": self.means,
            "claim": self.claims(),
            "params": self.params,
            "shading_norm": self.shading_norm,
            "seconds": {k: round(v, 4) for k, v in self.seconds.items()},
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ComparisonResult:
        """A result from :meth:`to_dict` (e.g. a server's answer): scores and directions, without
        the per-pixel results and renderings (enough for tables and :func:`plot`)."""
        methods = tuple(data["methods"])
        dirs = data["directions"]
        return cls(
            methods=methods,
            numbers=tuple(int(d["index"]) for d in dirs),
            directions=np.asarray([d["vector"] for d in dirs], np.float32).reshape(-1, 3),
            scores=np.asarray([data["scores"][m] for m in methods], np.float64),
            results={},
            images={},
            params=dict(data.get("params", {})),
            albedo=str(data.get("albedo", "white")),
            image_shape=(int(data["image_shape"][0]), int(data["image_shape"][1])),
            seconds=dict(data.get("seconds", {})),
            label=str(data.get("label", "")),
            shading_norm=dict(data.get("shading_norm", {"mode": "per_image"})),
        )

    def to_json(self, indent: int | None = 2) -> str:
        """:meth:`to_dict` as a JSON string."""
        return json.dumps(self.to_dict(), indent=indent)


# -- running the comparison --------------------------------------------------------------------


def _frame_geometry(frame: Frame, albedo: str, params: dict[str, dict[str, Any]]) -> _Geometry:
    if albedo not in ALBEDOS:
        raise ValueError(f"albedo must be one of {', '.join(ALBEDOS)}, got {albedo!r}")
    normal = np.ascontiguousarray(frame.need("normal", "to shade the comparison"), np.float32)
    depth = np.ascontiguousarray(frame.need("depth", "for the shape flow of the score"), np.float32)
    if normal.ndim != 3 or normal.shape[2] != 3:
        raise ValueError(f"frame normal must be (H, W, 3), got shape {normal.shape}")
    mask = (np.asarray(frame.mask) > 0.5) & np.isfinite(depth) & (depth > 0)
    mask &= dot(normal, normal) > 0.25
    alb = None
    if albedo == "frame":
        a = np.asarray(frame.need("albedo", "albedo='frame'"), np.float32)
        alb = np.ascontiguousarray(a if a.ndim == 3 else np.dstack([a, a, a]), np.float32)
    normal = np.where(mask[..., None], normal, np.float32(0.0)).astype(np.float32)
    return _Geometry(
        normal=normal,
        depth=np.where(mask, depth, np.float32(np.inf)).astype(np.float32),
        mask=np.asarray(mask),
        albedo=alb,
        image_height=int(frame.image_height),
        params=params,
    )


def compare(
    frame: Frame,
    methods: Sequence[str] = METHODS,
    directions: int | Sequence[int] = N_DIRECTIONS,
    params: Mapping[str, Mapping[str, Any]] | None = None,
    *,
    albedo: str = "white",
    keep_images: bool | Iterable[int] = True,
    label: str = "",
    shading_norm: str | float = "reference",
) -> ComparisonResult:
    """Shade ``frame`` with each method under each light direction and score it (LLA §7).

    Every rendering is scored with the congruence score (LLA Eq. 2,
    :func:`ops.congruence.congruence`) against the frame's depth over its coverage.

    Parameters
    ----------
    frame : a frame with ``normal`` (camera space), ``depth`` and coverage (``albedo`` too when
        ``albedo="frame"``).
    methods : names from :data:`METHODS`.
    directions : how many directions of the fixed sweep (1…21, the first N), or a list of
        direction numbers (1-based) of :func:`ops.directions.comparison_directions`.
    params : per-section overrides of :data:`DEFAULT_PARAMS`: ``"congruence"`` (keywords of
        :func:`ops.congruence.congruence`), ``"radiance_scaling"`` (``alpha``, ``gamma``,
        ``curvature_scale``, ``curvature_gain``), ``"exaggerated_shading"`` (keywords of
        :func:`ops.baselines.exaggerated_shading`), ``"light_warping"`` (``strength``,
        ``curvature_scale``, ``curvature_gain``), ``"light_alignment"`` (``sigmas`` σ_1…σ_{S−1}
        finest first, ``gamma``, the pyramid's ``base``/``factor``/``depth_sigma`` and other
        keywords of :func:`ops.light_alignment.align_light`).
    albedo : ``"white"`` (ρ = 1, default) or ``"frame"`` (the frame's albedo buffer).
    keep_images : keep every rendering (True), none (False), or those of these direction numbers
        (for :func:`contact_sheet`; 21 × 5 renderings of a 1080p frame take ~0.9 GB).
    label : a name for the input, carried into tables and plots.
    shading_norm : ``"reference"`` (default: every rendering on the scale of the frame's
        Lambert rendering under #1), ``"per_image"``, or a number (see the module docstring).

    Returns
    -------
    ComparisonResult
    """
    ms = _check_methods(methods)
    sweep = comparison_directions(N_DIRECTIONS)
    if isinstance(directions, int | np.integer) and not isinstance(directions, bool):
        if not 1 <= int(directions) <= N_DIRECTIONS:
            raise ValueError(f"directions must be in [1, {N_DIRECTIONS}], got {directions!r}")
        numbers = list(range(1, int(directions) + 1))
    else:
        numbers = [int(k) for k in directions]  # type: ignore[union-attr]
        if not numbers or any(not 1 <= k <= N_DIRECTIONS for k in numbers):
            raise ValueError(
                f"directions must be direction numbers in [1, {N_DIRECTIONS}], got {directions!r}"
            )
    if keep_images is True:
        keep = set(numbers)
    elif keep_images is False:
        keep = set()
    else:
        keep = {int(k) for k in keep_images}
    resolved = resolve_params(params)
    geo = _frame_geometry(frame, albedo, resolved)
    cong = dict(resolved["congruence"])
    if shading_norm == "reference":
        reference = score_image(
            _lambert(geo, sweep[0]), geo.depth, geo.mask, geo.normal, geo.image_height, **cong
        )
        cong["shading_norm"] = reference.shading_norm
        norm = {"mode": "reference", "value": reference.shading_norm}
    elif shading_norm == "per_image":
        norm = {"mode": "per_image", "value": None}
    elif isinstance(shading_norm, int | float) and not isinstance(shading_norm, bool):
        cong["shading_norm"] = float(shading_norm)
        norm = {"mode": "pinned", "value": float(shading_norm)}
    else:
        raise ValueError(
            f"shading_norm must be 'reference', 'per_image' or a number, got {shading_norm!r}"
        )

    scores = np.zeros((len(ms), len(numbers)), np.float64)
    results: dict[str, list[CongruenceResult]] = {m: [] for m in ms}
    images: dict[str, dict[int, F32]] = {m: {} for m in ms}
    seconds = {m: 0.0 for m in ms}
    seconds["score"] = 0.0
    for j, number in enumerate(numbers):
        light = sweep[number - 1]
        for i, m in enumerate(ms):
            t0 = time.perf_counter()
            img = _SHADERS[m](geo, light)
            t1 = time.perf_counter()
            res = score_image(img, geo.depth, geo.mask, geo.normal, geo.image_height, **cong)
            seconds[m] += t1 - t0
            seconds["score"] += time.perf_counter() - t1
            scores[i, j] = res.score
            results[m].append(res)
            if number in keep:
                images[m][number] = img
    return ComparisonResult(
        methods=ms,
        numbers=tuple(numbers),
        directions=np.ascontiguousarray(sweep[np.asarray(numbers) - 1], np.float32),
        scores=scores,
        results=results,
        images=images,
        params=resolved,
        albedo=albedo,
        image_shape=(int(geo.depth.shape[0]), int(geo.depth.shape[1])),
        seconds=seconds,
        label=label,
        shading_norm=norm,
    )


def score_frame(frame: Frame, *, maps: bool = False, **params: Any) -> dict[str, Any]:
    """The congruence score (LLA Eq. 2) of ``frame``'s beauty against its depth (``depict score``).

    Parameters
    ----------
    frame : a frame with ``beauty`` and ``depth`` (coverage from :attr:`Frame.mask`).
    maps : also return the per-pixel layers under ``"layers"``: ``congruence.X`` (score map),
        ``congruence.shading.X/Y`` and ``congruence.shape.X/Y`` (the two flows, camera x right /
        y up), ``congruence.weight.X`` — ready for ``frame.outputs``.
    **params : keywords of :func:`ops.congruence.congruence` (``gradient_scale``,
        ``integration_scale``, ``percentile``, ``depth_jump``).

    Returns
    -------
    dict with ``score``, ``shading_norm`` (the shading strength mapped to 1: pass it as
    ``shading_norm`` to score another rendering of the frame on this one's scale),
    ``analysis_shape``, ``image_shape``, ``params`` (the congruence parameters used) and, with
    ``maps``, ``layers``.
    """
    cong = {**DEFAULT_PARAMS["congruence"], **params}
    beauty = np.asarray(frame.need("beauty", "the image to score"), np.float32)
    depth = np.asarray(frame.need("depth", "for the shape flow of the score"), np.float32)
    normal = frame.buffers.get("normal")
    if normal is None:
        cong["shape"] = "depth"
    res = score_image(beauty, depth, frame.mask, normal, int(frame.image_height), **dict(cong))
    out: dict[str, Any] = {
        "score": res.score,
        "shading_norm": float(res.shading_norm),
        "analysis_shape": list(res.analysis_shape),
        "image_shape": list(depth.shape),
        "params": cong,
    }
    if maps:
        out["layers"] = congruence_layers(res)
    return out


def congruence_layers(res: CongruenceResult) -> dict[str, F32]:
    """Output channels of a score: ``congruence.X`` and the flows (see :func:`score_frame`)."""
    return {
        "congruence.X": res.score_map,
        "congruence.weight.X": res.weight,
        "congruence.shading.X": np.ascontiguousarray(res.shading_flow[..., 0]),
        "congruence.shading.Y": np.ascontiguousarray(res.shading_flow[..., 1]),
        "congruence.shape.X": np.ascontiguousarray(res.shape_flow[..., 0]),
        "congruence.shape.Y": np.ascontiguousarray(res.shape_flow[..., 1]),
    }


def frame_from_mesh(
    path: str | Path,
    width: int = 512,
    height: int = 512,
    *,
    azimuth_deg: float = 30.0,
    elevation_deg: float = 20.0,
    weld: bool = True,
) -> Frame:
    """Render a mesh into a frame for :func:`compare` (no AO: only the geometry is used).

    ``weld`` merges vertices that share a position whatever their texture coordinates or
    normals: meshes with UV seams (spot.obj) store split vertices whose normals are averaged on
    each side of the seam only, a crease in the shading normals that is not in the shape and
    that every enhancement amplifies. The comparison is about shape, so it welds by default.
    """
    from gbuffer.render import auto_camera, load_mesh, render

    mesh = load_mesh(path)
    if weld:
        mesh.merge_vertices(merge_tex=True, merge_norm=True)
    cam = auto_camera(
        mesh, width=width, height=height, azimuth_deg=azimuth_deg, elevation_deg=elevation_deg
    )
    return render(mesh, width, height, camera=cam, ao="none")


# -- pictures ----------------------------------------------------------------------------------


def plot(result: ComparisonResult, path: str | Path, title: str | None = None) -> Path:
    """Scores vs direction number, one line per method, means dashed (like LLA Fig. 13).

    Grazing directions (θ = 90°) are shaded light grey, those behind the object (θ > 90°)
    darker. Written with matplotlib's Agg backend, atomically; returns the path.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gbuffer.atomic import atomic_path

    path = Path(path)
    n = result.n_directions
    x = np.arange(1, n + 1)
    fig, ax = plt.subplots(figsize=(10, 4.8), dpi=110)
    for k in range(n):
        theta, _ = _direction_angles(result.directions[k])
        if theta > 90.5:
            ax.axvspan(k + 0.5, k + 1.5, color="0.86", lw=0)
        elif theta > 89.5:
            ax.axvspan(k + 0.5, k + 1.5, color="0.93", lw=0)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    means = result.means
    for i, m in enumerate(result.methods):
        c = colors[i % len(colors)]
        ax.plot(
            x,
            result.scores[i],
            "-o",
            color=c,
            ms=4,
            lw=1.6,
            label=f"{LABELS[m]} (mean {means[m]:.3f})",
        )
        ax.axhline(means[m], color=c, ls="--", lw=1.0, alpha=0.8)
    ax.set_xlim(0.5, n + 0.5)
    ax.set_xticks(x, [str(k) for k in result.numbers])
    ax.set_xlabel("light direction # (grey: grazing, darker: behind the object)")
    ax.set_ylabel("congruence score (LLA Eq. 2)")
    lo = float(result.scores.min())
    ax.set_ylim(max(0.0, lo - 0.05), min(1.0, float(result.scores.max()) + 0.05))
    ax.grid(axis="y", alpha=0.3)
    ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
    ax.set_title(title or f"Congruence scores{' - ' + result.label if result.label else ''}")
    fig.tight_layout()
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp)
    finally:
        plt.close(fig)
    return path


def _crop_box(mask: NDArray[np.bool_], margin: float = 0.04) -> tuple[int, int, int, int]:
    """(r0, r1, c0, c1): the covered bounding box with a margin, squared off where it fits."""
    h, w = mask.shape
    rows = np.nonzero(mask.any(axis=1))[0]
    cols = np.nonzero(mask.any(axis=0))[0]
    if rows.size == 0:
        return 0, h, 0, w
    pad = round(margin * max(h, w))
    r0, r1 = max(0, rows[0] - pad), min(h, rows[-1] + 1 + pad)
    c0, c1 = max(0, cols[0] - pad), min(w, cols[-1] + 1 + pad)
    return int(r0), int(r1), int(c0), int(c1)


def _score_colors(smap: F32, weight: F32) -> F32:
    """Per-pixel score in false colour (red = 0, blue = 1, LLA Fig. 12), dark grey off it."""
    import matplotlib

    cmap = matplotlib.colormaps["RdYlBu"]
    rgb = np.asarray(cmap(np.clip(smap, 0.0, 1.0))[..., :3], np.float32)
    bg = np.float32(0.15)
    wgt = np.clip(weight, 0.0, 1.0)[..., None]
    return np.asarray(rgb * wgt + bg * (1.0 - wgt), np.float32)


def _put_text(img: np.ndarray, text: str, org: tuple[int, int], scale: float) -> None:
    """White text with a black outline on an (H, W, 3) uint8 image, in place."""
    font = cv2.FONT_HERSHEY_SIMPLEX
    thick = max(1, round(scale * 1.6))
    cv2.putText(img, text, org, font, scale, (0, 0, 0), thick + 2, cv2.LINE_AA)
    cv2.putText(img, text, org, font, scale, (255, 255, 255), thick, cv2.LINE_AA)


def contact_sheet(
    result: ComparisonResult,
    path: str | Path,
    directions: Sequence[int] | None = None,
    *,
    tile: int = 200,
) -> Path:
    """Renderings with their per-pixel score maps, one row per direction (like LLA Fig. 12).

    Each method gets two columns: its rendering (sRGB-encoded) and its score map (red = low,
    blue = high; dark grey where nothing is scored), the mean score in the corner. Tiles are
    cropped to the object and ``tile`` pixels high. Directions default to those of
    :data:`SHEET_DIRECTIONS` that were kept, else all kept ones. Returns the path.
    """
    from gbuffer.preview import srgb_encode, write_png

    if directions is None:
        kept = set.intersection(*(set(result.images[m]) for m in result.methods))
        directions = [k for k in SHEET_DIRECTIONS if k in kept] or sorted(kept)
    directions = [int(k) for k in directions]
    if not directions:
        raise ValueError("contact_sheet: no direction to show (no rendering was kept)")
    if not (16 <= tile <= 2048):
        raise ValueError(f"tile must be in [16, 2048] pixels, got {tile!r}")
    first = result.results[result.methods[0]][0]
    mask = np.asarray(first.weight) > 0
    any_img = result.image(result.methods[0], directions[0])
    cover = np.any(any_img != 0, axis=-1) if any_img.ndim == 3 else any_img != 0
    r0, r1, c0, c1 = _crop_box(mask | cover)
    th = int(tile)
    tw = max(16, round(th * (c1 - c0) / max(1, r1 - r0)))

    def fit(rgb: np.ndarray) -> np.ndarray:
        crop = np.ascontiguousarray(rgb[r0:r1, c0:c1])
        return np.asarray(cv2.resize(crop, (tw, th), interpolation=cv2.INTER_AREA), np.float32)

    label_w = max(48, th // 3)
    head_h = max(28, th // 7)
    ncols = 2 * len(result.methods)
    sheet = np.full((head_h + th * len(directions), label_w + tw * ncols, 3), 0.0, np.float32)
    tiles_txt: list[tuple[str, tuple[int, int]]] = []
    for r, k in enumerate(directions):
        y = head_h + r * th
        for i, m in enumerate(result.methods):
            img = result.image(m, k)
            rgb = img if img.ndim == 3 else np.dstack([img, img, img])
            x = label_w + 2 * i * tw
            sheet[y : y + th, x : x + tw] = fit(srgb_encode(rgb))
            res = result.results[m][result._col(k)]
            sheet[y : y + th, x + tw : x + 2 * tw] = fit(_score_colors(res.score_map, res.weight))
            tiles_txt.append((f"{result.score(m, k):.3f}", (x + tw + 4, y + 4)))
        tiles_txt.append((f"#{k}", (6, y + th // 2)))
    out = (np.clip(sheet, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    # separators between method pairs
    for i in range(1, len(result.methods)):
        x = label_w + 2 * i * tw
        out[:, x : x + 1] = 90
    scale = max(0.35, th / 400.0)
    for i, m in enumerate(result.methods):
        x = label_w + 2 * i * tw
        _put_text(out, LABELS[m], (x + 4, head_h - 8), scale)
    for text, (x, y) in tiles_txt:
        _put_text(out, text, (x, y + int(22 * scale)), scale)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_png(out.astype(np.float32) / 255.0, path)
    return path
