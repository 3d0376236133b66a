"""The result of the comparison bench (:func:`analysis.compare.compare`): scores of each method
under each light direction, with tables, JSON and the paper's claim checked."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from analysis.methods import LABELS
from ops.congruence import CongruenceResult

F32 = NDArray[np.float32]


def direction_angles(d: NDArray[np.floating]) -> tuple[float, float]:
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
            theta, phi = direction_angles(self.directions[k])
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
            theta, phi = direction_angles(self.directions[k])
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
