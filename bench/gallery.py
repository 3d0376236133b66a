"""Before/after contact sheets of every operator family, for a person to look at.

Run ``make gallery`` (``.venv/bin/python -m bench.gallery``): renders a few real meshes from
``../shared/models`` (small, about 384 px high) and reads the Blender Cycles fixture
(``tests/fixtures/blender``), runs the operators through :func:`service.pipeline.run` and writes
labelled PNG sheets into ``gallery/`` (git-ignored):

- ``rs_mesh.png``: Radiance Scaling, every §5 scenario, before (γ = 0, or the renderer's beauty
  for ``lobes`` / ``beauty``) and after; ``rs_blender.png``: ``lobes`` and ``beauty`` on the
  Cycles render;
- ``lla_scales.png``: Light Alignment with the σ settings of LLA Figs. 7 and 9 (none, coarse
  scales only, fine scales only, the paper's {0.5, 0.3, 0.1, 0.2, 0.2}); ``lla_materials.png``:
  the specular and transmission guides of Fig. 8 (the lobe alone, then the whole image);
  ``lla_blender.png``: the ratio form on the Cycles render, with the shot's lights;
- ``usm_mesh.png`` / ``usm_blender.png``: 3D unsharp masking, depth-buffer unsharp masking and a
  plain 2-D unsharp mask of the same size, with their lightness changes;
- ``relief_<mesh>.png``: Apparent Relief, the descriptor colour code, each style and a painted
  ARM (``custom_arm.png``, passed by its path).

``make gallery`` runs :mod:`bench.gallery_corpus` first: every operator's defaults on the corpus
frames, in ``gallery/corpus/``; then :mod:`bench.gallery_masks`: steps restricted to one object
by Cryptomatte (``gallery/masks_blender.png``).

``--docs DIR`` also writes six pictures for the README (at least 800 px wide):
``rs_scenarios.png``, ``rs_blender.png``, ``lla_scales.png``, ``lla_materials.png``, ``usm.png``
and ``relief_styles.png`` (``make gallery`` then ``python -m bench.gallery --docs docs/images``
refreshes the committed ones). The meshes
come from ``../shared/models`` (``--models``); the script exits with a message when the folder
is absent.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, get_args

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import cv2
import numpy as np

import gbuffer
from bench.compare_meshes import VIEWS
from bench.sheets import (
    SIZE,
    Tile,
    change_pic,
    is_render,
    pic,
    rgb_pic,
    save,
    sheet,
    to_u8,
)
from gbuffer.frame import Frame
from ops import relief as rl
from ops.curvature import DEFAULT_GAIN
from ops.unsharp import plain_unsharp_mask
from service import pipeline
from service.operators.radiance_scaling import Scenario

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MODELS = Path(__file__).resolve().parents[2] / "shared" / "models"
BLENDER = ROOT / "tests" / "fixtures" / "blender"
DEFAULT_OUT = ROOT / "gallery"

#: Radiance Scaling scenarios (those of the operator, in the order of the paper's §5).
RS_SCENARIOS = tuple(s for s in get_args(Scenario) if s != "auto")
#: Scenarios that post-process the renderer's image (their "before" is the input beauty).
RS_POST = ("lobes", "beauty")
#: Radiance Scaling γ of the mesh sheets (the curvature gain is the operator's default).
RS_GAMMA = 2.5
#: Light Alignment σ_i (finest first, S = 6) after LLA Fig. 7 and Fig. 9.
LLA_SCALES: tuple[tuple[str, list[float]], ...] = (
    ("no alignment (sigma = 0)", [0.0, 0.0, 0.0, 0.0, 0.0]),
    ("coarse scales 0,0,.4,.3,.2", [0.0, 0.0, 0.4, 0.3, 0.2]),
    ("fine scales .9,.6,0,0,0", [0.9, 0.6, 0.0, 0.0, 0.0]),
    ("paper .5,.3,.1,.2,.2", [0.5, 0.3, 0.1, 0.2, 0.2]),
)
#: One key light for the Light Alignment sheets (camera space, towards the light).
LLA_LIGHT = "-0.5,0.5,0.7"
#: Size of every unsharp mask, relative to the image height.
USM_SIZE = 0.03
USM_AMOUNT = 1.5
DEPTH_USM_AMOUNT = 3.0

# -- inputs --------------------------------------------------------------------------------------


def find_mesh(models: Path, name: str) -> Path:
    for suffix in (".obj", ".ply"):
        path = models / f"{name}{suffix}"
        if path.is_file():
            return path
    raise SystemExit(f"gallery: mesh {name!r} not found in {models}")


def mesh_frame(models: Path, name: str, size: int = SIZE) -> Frame:
    """A square render of a shared mesh (welded, with SSAO for the ``ao`` scenario)."""
    from gbuffer.render import auto_camera, load_mesh, render

    mesh = load_mesh(find_mesh(models, name))
    mesh.merge_vertices(merge_tex=True, merge_norm=True)  # as analysis.compare.frame_from_mesh
    az, el = VIEWS.get(name, (30.0, 20.0))
    cam = auto_camera(mesh, width=size, height=size, azimuth_deg=az, elevation_deg=el)
    return render(mesh, size, size, camera=cam)


def blender_frame() -> Frame:
    exr = BLENDER / "cycles_multilayer.exr"
    if not exr.is_file():
        raise SystemExit(f"gallery: the Blender fixture {exr} is absent (see its README)")
    return gbuffer.read(exr, camera=BLENDER / "camera.json")


def blender_lights(frame: Frame) -> list[str]:
    """The fixture's two lights (tests/fixtures/blender/scene.json) in camera space: the sun as a
    directional light, the area light as a point light at its centre."""
    import json

    scene = json.loads((BLENDER / "scene.json").read_text())["lights"]
    assert frame.camera is not None and frame.camera.world_to_camera is not None
    w2c = np.asarray(frame.camera.world_to_camera, np.float64)
    sun = w2c[:3, :3] @ np.asarray(scene["Sun"]["direction_to_light"], np.float64)
    area = w2c @ np.append(np.asarray(scene["Area"]["location"], np.float64), 1.0)
    fmt = ",".join
    return [
        fmt(f"{v:.4f}" for v in sun / np.linalg.norm(sun)),
        "point:" + fmt(f"{v:.4f}" for v in area[:3]),
    ]


def apply(frame: Frame, op: str, **params: Any) -> Frame:
    return pipeline.run(frame, [{"op": op, "params": params}])


# -- Radiance Scaling ----------------------------------------------------------------------------


def rs_pair(frame: Frame, scenario: str, **params: Any) -> tuple[np.ndarray, np.ndarray]:
    """(before, after) pictures of one scenario: the input beauty for the post-processing
    scenarios, the same shading with γ = 0 (σ ≡ 1) for the deferred ones."""
    params = {"gamma": RS_GAMMA, **params}
    after = pic(apply(frame, "radiance_scaling", scenario=scenario, **params))
    if scenario in RS_POST:
        return pic(frame), after
    params["gamma"] = 0.0
    return pic(apply(frame, "radiance_scaling", scenario=scenario, **params)), after


def radiance_scaling(mesh: Frame, mesh_name: str, blender: Frame) -> dict[str, Any]:
    pairs = {s: rs_pair(mesh, s) for s in RS_SCENARIOS}
    rows: list[list[Tile]] = []
    for half in (RS_SCENARIOS[:5], RS_SCENARIOS[5:]):
        rows.append([(pairs[s][0], f"{s}: before") for s in half])
        rows.append([(pairs[s][1], f"{s}: after") for s in half])
    mesh_sheet = sheet(
        rows,
        f"Radiance Scaling (Vergne et al. 2011, sec. 5), every scenario, on {mesh_name}: gamma "
        f"{RS_GAMMA:g}, curvature gain {DEFAULT_GAIN:g}; before = the input (lobes, beauty) or the "
        "same shading with gamma 0",
        frame=mesh,
    )
    # The fixture's objects fill its small frame (low curvature per image height): a gain above
    # the default shows them without saturating.
    fixture = {"gamma": 3.0, "gain": 0.1}
    bl: dict[str, Any] = {s: rs_pair(blender, s, **fixture) for s in RS_POST}
    before = bl["lobes"][0]
    bl["change"] = change_pic(before, bl["lobes"][1], blender.mask, 0.15)
    blender_sheet = sheet(
        [
            [
                (before, "Cycles beauty"),
                (bl["lobes"][1], "lobes (Eq. 4)"),
                (bl["beauty"][1], "beauty as one lobe"),
            ],
            [
                (np.full_like(before, 0.5), "lightness change|blue darker, red|lighter, +-0.15"),
                (bl["change"], "lobes"),
                (change_pic(before, bl["beauty"][1], blender.mask, 0.15), "beauty as one lobe"),
            ],
        ],
        "Radiance Scaling on the Blender Cycles fixture (160x120, shown x2): gamma 3 (the "
        "default), gain 0.1",
        height=240,
    )
    return {"mesh": mesh_sheet, "blender": blender_sheet, "pairs": pairs, "blender_pairs": bl}


# -- Light Alignment -----------------------------------------------------------------------------


def lla(frame: Frame, **params: Any) -> Frame:
    return apply(frame, "light_alignment", form="relight", **params)


def light_alignment(mesh: Frame, mesh_name: str, blender: Frame) -> dict[str, Any]:
    diffuse = {"lights": [LLA_LIGHT], "components": ["diffuse"], "specular": "none"}
    scales = [(pic(lla(mesh, sigmas=s, **diffuse)), label) for label, s in LLA_SCALES]
    scales_sheet = sheet(
        [scales],
        f"Light Alignment (Mestres et al. 2021, Figs. 7, 9) on {mesh_name}: diffuse guide, "
        "Lambert, one light, S = 6, sigma_i finest first",
        frame=mesh,
    )

    spec = {
        "lights": [LLA_LIGHT],
        "components": ["specular"],
        "specular": "blinn_phong",
        "shininess": 48.0,
        "specular_color": 0.5,
    }
    spec_sig = [0.4, 0.2, 0.0, 0.3]  # Fig. 8 a
    spec0, spec1 = lla(mesh, sigmas=[0.0] * 4, **spec), lla(mesh, sigmas=spec_sig, **spec)
    trans = {
        "lights": ["0.3,0.4,-0.85"],  # behind the object: its light comes through it
        "components": ["transmission"],
        "transmission_weight": 1.0,
        "specular": "none",
        "ambient": 0.05,
    }
    trans_sig = [0.7, 0.3, 0.25, 0.6]  # Fig. 8 c, d
    trans0, trans1 = lla(mesh, sigmas=[0.0] * 4, **trans), lla(mesh, sigmas=trans_sig, **trans)
    materials = [
        [
            (pic(spec0, "specular", 1.0), "specular lobe: original"),
            (pic(spec1, "specular", 1.0), "specular lobe: aligned|sigma .4,.2,0,.3"),
            (pic(spec0), "whole image: original"),
            (pic(spec1), "whole image: aligned"),
        ],
        [
            (pic(trans0, "transmission"), "transmission lobe: original"),
            (pic(trans1, "transmission"), "transmission lobe: aligned|sigma .7,.3,.25,.6"),
            (pic(trans0), "whole image: original"),
            (pic(trans1), "whole image: aligned"),
        ],
    ]
    materials_sheet = sheet(
        materials,
        "Light Alignment guides (LLA Fig. 8, S = 5), relight form: reflected view vector "
        "(Blinn-Phong, lobe shown +1 stop), refracted view vector (back light)",
        frame=mesh,
    )

    lights = blender_lights(blender)
    ratio = apply(blender, "light_alignment", form="ratio", lights=lights)
    ratio_d = apply(blender, "light_alignment", form="ratio", lights=lights, components=["diffuse"])
    b0 = pic(blender)
    blender_rows: list[list[Tile]] = [
        [
            (b0, "Cycles beauty"),
            (pic(ratio), "ratio form|diffuse + specular"),
            (pic(ratio_d), "ratio form|diffuse only"),
        ],
        [
            (np.full_like(b0, 0.5), "lightness change|blue darker, red|lighter, +-0.25"),
            (change_pic(b0, pic(ratio), blender.mask, 0.25), "diffuse + specular"),
            (change_pic(b0, pic(ratio_d), blender.mask, 0.25), "diffuse only"),
        ],
    ]
    blender_sheet = sheet(
        blender_rows,
        "Light Alignment, ratio form, on the Cycles fixture (x2), with the sun and area light of "
        "the shot",
        height=240,
    )
    return {
        "scales": scales_sheet,
        "materials": materials_sheet,
        "blender": blender_sheet,
        "scale_tiles": scales,
        "material_tiles": materials,
    }


# -- unsharp masking -----------------------------------------------------------------------------


def unsharp_tiles(frame: Frame) -> list[list[Tile]]:
    before = frame.buffers["beauty"]
    usm = apply(frame, "unsharp_masking", amount=USM_AMOUNT, sigma_fraction=USM_SIZE)
    dusm = apply(frame, "depth_unsharp_masking", amount=DEPTH_USM_AMOUNT, sigma=USM_SIZE)
    plain = plain_unsharp_mask(before, USM_SIZE, USM_AMOUNT)
    b = pic(frame)
    outs = [
        (rgb_pic(frame, plain), f"plain 2-D USM|amount {USM_AMOUNT:g}"),
        (pic(usm), f"3D USM (along surfaces)|amount {USM_AMOUNT:g}"),
        (pic(dusm), f"depth-buffer USM|amount {DEPTH_USM_AMOUNT:g}"),
    ]
    # the fixture's background is part of its picture (plain USM changes it); renders: surface
    where = frame.mask if is_render(frame) else np.ones(frame.shape, np.float32)
    changes = [(change_pic(b, img, where, 0.2), label) for img, label in outs]
    return [
        [(b, "original"), *outs],
        [(np.full_like(b, 0.5), "lightness change|blue darker, red|lighter, +-0.2"), *changes],
    ]


def unsharp(mesh: Frame, mesh_name: str, blender: Frame) -> dict[str, Any]:
    size = f"sigma {USM_SIZE:g} of the image height"
    mesh_rows = unsharp_tiles(mesh)
    blender_rows = unsharp_tiles(blender)
    return {
        "mesh": sheet(
            mesh_rows,
            f"Unsharp masking on {mesh_name}, {size}: plain 2-D, 3D (Ritschel et al. 2008), "
            "depth buffer (Luft et al. 2006)",
            frame=mesh,
        ),
        "blender": sheet(
            blender_rows,
            f"Unsharp masking on the Blender Cycles fixture (shown x2), {size}",
            height=240,
        ),
        "mesh_rows": mesh_rows,
        "blender_rows": blender_rows,
    }


# -- Apparent Relief -----------------------------------------------------------------------------


def custom_arm(size: int = 128) -> np.ndarray:
    """A painted ARM (Apparent Relief §3): white paper, valleys inked black, cups dark grey,
    saddles mid grey, ridges light grey."""
    arm = np.ones((size, size), np.float32)
    s = 0.75 / math.sqrt(2.0)
    arm = rl.paint_arm(arm, (0.05, -0.8), 0.0, radius=0.55)  # concave (valleys)
    arm = rl.paint_arm(arm, (-s, -s), 0.15, radius=0.45)  # cups
    arm = rl.paint_arm(arm, (s, -s), 0.5, radius=0.35)  # saddles
    arm = rl.paint_arm(arm, (0.8, 0.05), 0.6, radius=0.4)  # convex (ridges)
    return arm


#: (label, docs label, apparent_relief parameters; ``ARM`` stands for the painted ARM's path)
RELIEF_RUNS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("descriptor colour code", "descriptor", {"style": "descriptor"}),
    ("cel: convex black,|concave white", "cel", {"style": "cel"}),
    ("counter shading", "counter", {"style": "counter"}),
    ("X-Toon", "X-Toon", {"style": "xtoon"}),
    (
        "mask: exaggerated shading|on convex_only",
        "mask (ES)",
        {"style": "mask", "arm": "convex_only", "effect": {"op": "exaggerated_shading"}},
    ),
    ("cel: painted ARM|(passed as a file)", "painted ARM", {"style": "cel", "arm": "ARM"}),
)


def relief(frame: Frame, arm_path: Path) -> list[tuple[np.ndarray, str, str]]:
    """(picture, label, docs label) of the input, exaggerated shading and every relief run."""
    out = [
        (pic(frame), "original", "original"),
        (pic(apply(frame, "exaggerated_shading")), "exaggerated shading", "ES"),
    ]
    for label, short, params in RELIEF_RUNS:
        p = {**params, "arm": str(arm_path)} if params.get("arm") == "ARM" else params
        styled = p["style"] != "mask"  # mask blends two shadings: a rendering, like the input
        out.append((pic(apply(frame, "apparent_relief", **p), styled=styled), label, short))
    return out


def arm_tile(arm: np.ndarray) -> np.ndarray:
    """The painted ARM (grey) over the template's colour code (Fig. 1a domain)."""
    template = rl.arm_template(256)
    grey = cv2.resize(arm, (256, 256), interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray(0.65 * grey[..., None] + 0.35 * template, np.float32)


def apparent_relief(frames: dict[str, Frame], out: Path, written: list[Path]) -> dict[str, Any]:
    arm = custom_arm()
    arm_path = out / "custom_arm.png"
    save(np.repeat(to_u8(arm)[..., None], 3, axis=2), arm_path, written)
    result: dict[str, Any] = {}
    for name, frame in frames.items():
        runs = relief(frame, arm_path)
        tiles: list[Tile] = [(img, label) for img, label, _ in runs]
        tiles.append((arm_tile(arm), "painted ARM over|the template"))
        result[name] = sheet(
            [tiles[:5], tiles[5:]],
            f"Apparent Relief (Vergne et al. 2008) on {name}: descriptor (Fig. 1a), styles "
            "(Figs. 1-2), an ARM painted with paint_arm",
            frame=frame,
        )
        result[f"{name}_runs"] = runs
    return result


# -- docs ----------------------------------------------------------------------------------------


#: Sheet settings shared by the README pictures (small labels, square tiles).
DOCS_SHEET_STYLE: dict[str, Any] = {
    "gap": 2,
    "label_scale": 0.5,
    "title_scale": 0.55,
    "square": True,
}


def docs_pictures(
    frames: dict[str, Frame],
    names: dict[str, str],
    blender: Frame,
    rs: dict[str, Any],
    la: dict[str, Any],
    usm: dict[str, Any],
    rel: dict[str, Any],
    out: Path,
    written: list[Path],
) -> None:
    """A few pictures (at least 800 px wide) for the README, one per operator family."""
    docs_radiance_scaling(frames[names["rs"]], rs, out, written)
    docs_light_alignment(frames[names["lla"]], la, out, written)
    docs_unsharp(frames[names["usm"]], usm, out, written)
    docs_relief(frames[names["relief"]], rel[f"{names['relief']}_runs"], out, written)


def docs_radiance_scaling(mesh: Frame, rs: dict[str, Any], out: Path, written: list[Path]) -> None:
    """``rs_scenarios.png`` (4 scenarios before / after) and ``rs_blender.png``."""
    chosen = ("lobes", "toon", "lit_sphere", "mirror")
    pairs = rs["pairs"]
    rows = [
        [(pairs[s][0], f"{s}: before") for s in chosen],
        [(pairs[s][1], f"{s}: after") for s in chosen],
    ]
    title = f"Radiance Scaling, 4 of the 10 scenarios (gamma {RS_GAMMA:g})"
    save(
        sheet(rows, title, height=204, frame=mesh, **DOCS_SHEET_STYLE),
        out / "rs_scenarios.png",
        written,
    )

    bl = rs["blender_pairs"]
    save(
        sheet(
            [
                [
                    (bl["lobes"][0], "Cycles beauty"),
                    (bl["lobes"][1], "Radiance Scaling"),
                    (bl["change"], "blue darker, red lighter"),
                ]
            ],
            "Radiance Scaling of a Blender Cycles render's lobes (Eq. 4)",
            height=215,
            **DOCS_SHEET_STYLE,
        ),
        out / "rs_blender.png",
        written,
    )


def docs_light_alignment(mesh: Frame, la: dict[str, Any], out: Path, written: list[Path]) -> None:
    """``lla_scales.png`` (the σ settings) and ``lla_materials.png`` (specular, transmission)."""
    short = ("sigma = 0", "coarse scales", "fine scales", "paper's sigma_i")
    scales = [(img, text) for (img, _), text in zip(la["scale_tiles"], short, strict=True)]
    save(
        sheet(
            [scales],
            "Light Alignment: diffuse, enhancing coarse, fine or all scales",
            height=213,
            frame=mesh,
            **DOCS_SHEET_STYLE,
        ),
        out / "lla_scales.png",
        written,
    )

    mt = la["material_tiles"]
    save(
        sheet(
            [
                [
                    (mt[0][0][0], "specular: original"),
                    (mt[0][1][0], "specular: aligned"),
                    (mt[1][0][0], "transmission"),
                    (mt[1][1][0], "transm.: aligned"),
                ]
            ],
            "Light Alignment of specular and transmission (LLA Fig. 8)",
            height=213,
            frame=mesh,
            **DOCS_SHEET_STYLE,
        ),
        out / "lla_materials.png",
        written,
    )


def docs_unsharp(mesh: Frame, usm: dict[str, Any], out: Path, written: list[Path]) -> None:
    """``usm.png``: the mesh's and the Cycles render's unsharp masks side by side."""
    labels = ("original", "plain 2-D USM", "3D USM", "depth USM")
    rows = [
        [(img, text) for (img, _), text in zip(src[0], labels, strict=True)]
        for src in (usm["mesh_rows"], usm["blender_rows"])
    ]
    save(
        sheet(
            rows,
            "Unsharp masking: plain 2-D, 3D (along surfaces), depth buffer",
            height=[213, 160],
            frame=mesh,
            **DOCS_SHEET_STYLE,
        ),
        out / "usm.png",
        written,
    )


def docs_relief(
    mesh: Frame, runs: list[tuple[np.ndarray, str, str]], out: Path, written: list[Path]
) -> None:
    """``relief_styles.png``: the descriptor colour code and the styles (``runs`` of
    :func:`relief`, without the original and ES)."""
    picked = [(img, short) for img, _, short in runs if short not in ("original", "ES")]
    save(
        sheet(
            [picked[:3], picked[3:]],
            "Apparent Relief: descriptor colour code and styles",
            height=268,
            frame=mesh,
            **DOCS_SHEET_STYLE,
        ),
        out / "relief_styles.png",
        written,
    )


# -- main ----------------------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("out", nargs="?", type=Path, default=DEFAULT_OUT, help="output folder")
    ap.add_argument("--models", type=Path, default=DEFAULT_MODELS, help="mesh folder")
    ap.add_argument("--docs", type=Path, default=None, help="also write README pictures here")
    args = ap.parse_args(argv)
    if not args.models.is_dir():
        print(
            f"gallery: the mesh folder {args.models} is absent (the shared test meshes are "
            "checked out beside the repository as ../shared/models; pass --models DIR)",
            file=sys.stderr,
        )
        return 2
    t0 = time.perf_counter()
    written: list[Path] = []
    out: Path = args.out
    blender = blender_frame()
    names = {"rs": "igea", "lla": "igea", "usm": "stanford-bunny", "relief": "stanford-bunny"}
    relief_names = ("stanford-bunny", "ogre")
    wanted = dict.fromkeys([*names.values(), *relief_names])
    frames = {n: mesh_frame(args.models, n) for n in wanted}

    rs = radiance_scaling(frames[names["rs"]], names["rs"], blender)
    save(rs["mesh"], out / "rs_mesh.png", written)
    save(rs["blender"], out / "rs_blender.png", written)

    la = light_alignment(frames[names["lla"]], names["lla"], blender)
    save(la["scales"], out / "lla_scales.png", written)
    save(la["materials"], out / "lla_materials.png", written)
    save(la["blender"], out / "lla_blender.png", written)

    usm = unsharp(frames[names["usm"]], names["usm"], blender)
    save(usm["mesh"], out / "usm_mesh.png", written)
    save(usm["blender"], out / "usm_blender.png", written)

    rel = apparent_relief({n: frames[n] for n in relief_names}, out, written)
    for name in relief_names:
        save(rel[name], out / f"relief_{name}.png", written)

    if args.docs is not None:
        docs_pictures(frames, names, blender, rs, la, usm, rel, args.docs, written)
    print(f"gallery: {len(written)} files in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
