"""The LLA comparison bench on real meshes (Mestres et al. 2021, §7, Figs. 12-13).

Renders each mesh (camera-space normals and depth, white surface), shades it with every method
of :mod:`analysis.methods` under the fixed 21-direction sweep, scores each rendering with the
congruence score (LLA Eq. 2) and writes, into the output folder:

- ``<mesh>.md`` / ``<mesh>.json``: the table (directions × methods, means) and the raw scores;
- ``<mesh>_plot.png``: scores vs direction (like Fig. 13);
- ``<mesh>_sheet.png``: renderings and score maps for directions #1, 3, 4, 6, 9, 16 (like Fig. 12);
- ``summary.md`` / ``summary.json``: means per mesh and method, and the paper's claim checked
  per mesh (Light Alignment above Lambert at every direction, best mean);
- with ``--terms``, ``<mesh>_terms.md``: the direction factor |v_shape·v_shading| and the
  magnitude factor 1 − ⌊e_shape − e_shading⌋ of Eq. 2 averaged separately (a diagnostic of
  *why* a method scores what it does).

Run::

    .venv/bin/python -m bench.compare_meshes gallery/compare
    .venv/bin/python -m bench.compare_meshes OUT --meshes spot,ogre --size 1024 \\
        --set light_alignment.gamma=2 --set congruence.integration_scale=0.02

Meshes come from ``../shared/models`` (``--models``); the script exits with a message when the
folder is absent.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from analysis.compare import compare, frame_from_mesh
from analysis.methods import LABELS, METHODS
from analysis.pictures import contact_sheet, plot
from analysis.result import ComparisonResult
from service.cli import args as cli_args

#: Views (azimuth, elevation in degrees) that show each mesh's front (checked by eye).
VIEWS: dict[str, tuple[float, float]] = {
    "spot": (150.0, 20.0),
    "stanford-bunny": (30.0, 20.0),
    "nefertiti": (0.0, -80.0),
    "ogre": (20.0, 10.0),
    "igea": (30.0, 20.0),
    "fandisk": (30.0, 20.0),
}
DEFAULT_MESHES = ("spot", "stanford-bunny", "nefertiti", "ogre")
DEFAULT_MODELS = Path(__file__).resolve().parents[1].parent / "shared" / "models"


def parse_sets(items: list[str]) -> dict[str, dict[str, Any]]:
    """``section.key=value`` items -> ``{section: {key: value}}`` (values parsed as JSON)."""
    try:
        return cli_args.parse_sets(items)
    except cli_args.UsageError as exc:
        raise SystemExit(str(exc)) from None


def find_mesh(models: Path, name: str) -> Path:
    for suffix in (".obj", ".ply", ""):
        p = models / f"{name}{suffix}"
        if p.is_file():
            return p
    raise SystemExit(f"mesh {name!r} not found in {models}")


def summary_markdown(results: dict[str, ComparisonResult]) -> str:
    """Means (methods × meshes) and the claim per mesh."""
    names = list(results)
    methods = next(iter(results.values())).methods
    lines = [
        "| method | " + " | ".join(names) + " | average |",
        "|---|" + "---:|" * (len(names) + 1),
    ]
    for m in methods:
        vals = [results[n].means[m] for n in names]
        cells = []
        for n, v in zip(names, vals, strict=True):
            best = max(results[n].means.values())
            cells.append(f"**{v:.3f}**" if v == best else f"{v:.3f}")
        lines.append(f"| {LABELS[m]} | " + " | ".join(cells) + f" | {sum(vals) / len(vals):.3f} |")
    lines.append("")
    lines.append(
        "| mesh | LLA > Lambert (directions) | min margin | LLA best mean | LLA mean − best other |"
    )
    lines.append("|---|---:|---:|---|---:|")
    for n in names:
        c = results[n].claims()
        if not c or "baseline" not in c:
            continue
        other = min(c["mean_margin_over_others"].values())
        miss = c["directions_not_above_baseline"]
        lines.append(
            f"| {n} | {c['above_baseline_count']}/{results[n].n_directions}"
            + (f" (not #{', #'.join(map(str, miss))})" if miss else "")
            + f" | {c['min_margin_over_baseline']:+.3f} | {'yes' if c['best_mean'] else 'no'}"
            + f" | {other:+.3f} |"
        )
    return "\n".join(lines)


def score_terms(result: ComparisonResult) -> dict[str, dict[str, list[float]]]:
    """The two factors of Eq. 2 separately, per method and direction (a diagnostic).

    With w = e_shape × coverage: ``direction`` = Σ w |v_shape·v_shading| / Σ w and ``magnitude``
    = Σ w (1 − ⌊e_shape − e_shading⌋) / Σ w; ``full`` = Σ w · score_map / Σ w. Computed from the
    full-resolution maps of :class:`ops.congruence.CongruenceResult` (upsampled from the
    analysis grid), so ``full`` matches the score to about 1e-2, not exactly. ``no_flow`` = the
    w-weighted fraction of pixels with (almost) no shading flow, e_shading < 0.01 (masked,
    black or flat regions: their direction factor is 0).
    """
    out: dict[str, dict[str, list[float]]] = {}
    for m in result.methods:
        terms: dict[str, list[float]] = {
            "direction": [],
            "magnitude": [],
            "full": [],
            "no_flow": [],
        }
        for res in result.results[m]:
            w = res.shape_strength * res.weight
            den = float(w.sum()) or 1.0
            dot = abs((res.shading_flow * res.shape_flow).sum(axis=-1))
            mag = 1.0 - (res.shape_strength - res.shading_strength).clip(0.0, 1.0)
            terms["direction"].append(float((w * dot).sum()) / den)
            terms["magnitude"].append(float((w * mag).sum()) / den)
            terms["full"].append(float((w * res.score_map).sum()) / den)
            terms["no_flow"].append(float((w * (res.shading_strength < 0.01)).sum()) / den)
        out[m] = terms
    return out


def terms_markdown(terms: dict[str, dict[str, list[float]]], numbers: tuple[int, ...]) -> str:
    """Means of the factors per method over the directions, then direction / magnitude factors
    at each direction."""
    lines = [
        "| method | direction factor | magnitude factor | full | no shading flow |",
        "|---|---:|---:|---:|---:|",
    ]
    for m, t in terms.items():
        lines.append(
            f"| {LABELS[m]} | {sum(t['direction']) / len(numbers):.3f} | "
            f"{sum(t['magnitude']) / len(numbers):.3f} | {sum(t['full']) / len(numbers):.3f} | "
            f"{sum(t['no_flow']) / len(numbers):.3f} |"
        )
    lines += ["", "| # | " + " | ".join(f"{LABELS[m]} dir / mag" for m in terms) + " |"]
    lines.append("|---:|" + "---:|" * len(terms))
    for j, k in enumerate(numbers):
        cells = [f"{t['direction'][j]:.3f} / {t['magnitude'][j]:.3f}" for t in terms.values()]
        lines.append(f"| {k} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="output folder (created)")
    ap.add_argument("--meshes", default=",".join(DEFAULT_MESHES), help="comma list of names")
    ap.add_argument("--models", type=Path, default=DEFAULT_MODELS, help="folder of the meshes")
    ap.add_argument("--size", type=int, default=512, help="render width and height (pixels)")
    ap.add_argument("--methods", default=",".join(METHODS), help="comma list of methods")
    ap.add_argument("--albedo", default="white", choices=["white", "frame"])
    ap.add_argument(
        "--directions", type=int, default=21, help="first N directions of the sweep (1-21)"
    )
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="parameter override, e.g. light_alignment.gamma=2 or congruence.percentile=99",
    )
    ap.add_argument(
        "--shading-norm",
        default="reference",
        choices=["reference", "per_image"],
        help="scale of the shading strengths (analysis.compare)",
    )
    ap.add_argument("--no-sheet", action="store_true", help="skip the contact sheets")
    ap.add_argument(
        "--terms",
        action="store_true",
        help="also write <mesh>_terms.md: Eq. 2's direction and magnitude factors separately",
    )
    ap.add_argument("--quiet", action="store_true", help="do not print the tables")
    return ap


def compare_mesh(
    args: argparse.Namespace, name: str, methods: list[str], params: dict[str, dict[str, Any]]
) -> ComparisonResult:
    """Render one mesh, compare the methods on it, write its files and print its timings."""
    path = find_mesh(args.models, name)
    az, el = VIEWS.get(name, (30.0, 20.0))
    t0 = time.perf_counter()
    frame = frame_from_mesh(path, args.size, args.size, azimuth_deg=az, elevation_deg=el)
    t1 = time.perf_counter()
    res = compare(
        frame,
        methods=methods,
        directions=args.directions,
        params=params,
        albedo=args.albedo,
        keep_images=not args.no_sheet,
        label=name,
        shading_norm=args.shading_norm,
    )
    t2 = time.perf_counter()
    head = (
        f"## {name} ({args.size}×{args.size}, view az {az:g}° el {el:g}°, albedo {args.albedo})\n\n"
    )
    view = {"azimuth_deg": az, "elevation_deg": el, "size": args.size}
    write_mesh_files(args, name, res, head, view)
    t3 = time.perf_counter()
    if not args.quiet:
        print(head + res.table_markdown() + "\n")
    print(
        f"[{name}] render {t1 - t0:.1f} s, compare {t2 - t1:.1f} s, pictures {t3 - t2:.1f} s",
        flush=True,
    )
    return res


def write_mesh_files(
    args: argparse.Namespace,
    name: str,
    res: ComparisonResult,
    head: str,
    view: dict[str, float],
) -> None:
    """``<mesh>.md``, ``<mesh>.json``, the plot, the sheet and (``--terms``) the factors."""
    (args.out / f"{name}.md").write_text(head + res.table_markdown() + "\n")
    data = res.to_dict()
    data["view"] = view
    (args.out / f"{name}.json").write_text(json.dumps(data, indent=2))
    plot(res, args.out / f"{name}_plot.png", title=f"Congruence scores - {name}")
    if not args.no_sheet:
        contact_sheet(res, args.out / f"{name}_sheet.png")
    if args.terms:
        terms = score_terms(res)
        (args.out / f"{name}_terms.md").write_text(
            f"## {name}: factors of Eq. 2 (diagnostic)\n\n"
            + terms_markdown(terms, res.numbers)
            + "\n"
        )
        data["terms"] = terms
        (args.out / f"{name}.json").write_text(json.dumps(data, indent=2))


def write_summary(
    args: argparse.Namespace,
    params: dict[str, dict[str, Any]],
    results: dict[str, ComparisonResult],
) -> str:
    """``summary.md`` and ``summary.json``; returns the summary's tables."""
    summary = summary_markdown(results)
    (args.out / "summary.md").write_text(
        f"# Comparison bench ({args.size}×{args.size}, albedo {args.albedo}, "
        f"shading strengths {args.shading_norm})\n\n"
        + (f"Overrides: `{json.dumps(params)}`\n\n" if params else "")
        + summary
        + "\n"
    )
    (args.out / "summary.json").write_text(
        json.dumps(
            {
                "size": args.size,
                "albedo": args.albedo,
                "overrides": params,
                "meshes": {
                    n: {"means": r.means, "claim": r.claims(), "scores": r.to_dict()["scores"]}
                    for n, r in results.items()
                },
            },
            indent=2,
        )
    )
    return summary


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if not args.models.is_dir():
        print(f"models folder {args.models} is absent: nothing to compare", file=sys.stderr)
        return 2
    params = parse_sets(args.set)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    args.out.mkdir(parents=True, exist_ok=True)
    results: dict[str, ComparisonResult] = {}
    for name in [m.strip() for m in args.meshes.split(",") if m.strip()]:
        results[name] = compare_mesh(args, name, methods, params)
    print(write_summary(args, params, results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
