"""A corpus of real frames: Blender Cycles renders of the scenes in ``corpus/`` and Depict's own
renders of meshes, each with its camera and key lights.

Commands (``python -m bench.corpus COMMAND --help``)::

    python -m bench.corpus render [--size 240p|540p|1080p] [--samples 16|512] [--scene NAME]
    python -m bench.corpus meshes [--size ...] [--models DIR]
    python -m bench.corpus ci        # re-render the committed CI subset (tests/fixtures/corpus)
    python -m bench.corpus list [DIR]

``render`` runs Blender (``blender -b --factory-startup --python corpus/SCENE.py -- ...``) once
per scene, size and sample count and writes ``SCENE_SIZE_Nspp.exr`` with its
``.camera.json`` and ``.lights.json`` into ``corpus/frames/`` (git-ignored). ``meshes`` renders
the meshes of a folder with :func:`gbuffer.render.render` into ``mesh_NAME_SIZE.exr`` (the
camera is in the file; the lights file holds the render's lights). ``ci`` renders
:data:`CI_FRAMES` and stores them with :func:`pack`: radiance passes as HALF, Depth, Position,
Normal and IndexOB as FLOAT, ZIP, Blender's header and channel names kept.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from gbuffer.frame import Frame

ROOT = Path(__file__).resolve().parents[1]
SCENES_DIR = ROOT / "corpus"
#: Where ``render`` and ``meshes`` write (git-ignored).
OUT_DIR = SCENES_DIR / "frames"
#: The committed subset the quality tests run on.
CI_DIR = ROOT / "tests" / "fixtures" / "corpus"
DEFAULT_MODELS = ROOT.parent / "shared" / "models"
#: Frame sizes: name -> (width, height). The scenes' cameras fit the sensor vertically, so
#: every size frames the same height (240p is a 4:3 centre of the 16:9 view).
SIZES: dict[str, tuple[int, int]] = {
    "240p": (320, 240),
    "540p": (960, 540),
    "1080p": (1920, 1080),
}
SAMPLES = (16, 512)
#: (scene, size, samples) of the committed subset: every scene at 240p and 16 samples (the
#: noise a preview or an early render has), and one at 512 samples.
CI_FRAMES: tuple[tuple[str, str, int], ...] = (
    ("rock", "240p", 16),
    ("still_life", "240p", 16),
    ("metal", "240p", 16),
    ("glass", "240p", 16),
    ("spot", "240p", 16),
    ("rock", "240p", 512),
)
#: Blender passes stored as 32-bit float by :func:`pack` (geometry and ids); the rest is HALF.
FLOAT_PASSES = ("Depth", "Position", "Normal", "IndexOB")


def scene_names() -> list[str]:
    """The scene scripts in ``corpus/`` (every ``*.py`` but the shared ``scenelib.py``)."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.py") if p.stem != "scenelib")


def stem(scene: str, size: str, samples: int) -> str:
    return f"{scene}_{size}_{samples}spp"


# -- the frames of a folder ----------------------------------------------------------------------


@dataclass(frozen=True)
class CorpusFrame:
    """One frame of the corpus: the EXR and its sidecar files (``None`` when absent)."""

    exr: Path
    camera: Path | None
    lights: Path | None

    @property
    def name(self) -> str:
        return self.exr.stem

    def light_strings(self) -> list[str]:
        """The key lights in camera space, as Depict light strings (empty without a file)."""
        if self.lights is None:
            return []
        return list(json.loads(self.lights.read_text())["lights"])

    def read(self) -> Frame:
        import gbuffer  # here: rendering needs none of Depict's imports

        return gbuffer.read(self.exr, camera=self.camera)


def find_frames(folder: Path, names: Iterable[str] = ()) -> list[CorpusFrame]:
    """The frames of ``folder`` (sorted), or only those whose name contains one of ``names``."""
    wanted = tuple(names)
    out = []
    for exr in sorted(p for p in folder.glob("*.exr") if not p.name.startswith(".")):
        if wanted and not any(w in exr.stem for w in wanted):
            continue
        camera = exr.with_suffix(".camera.json")
        lights = exr.with_suffix(".lights.json")
        out.append(
            CorpusFrame(
                exr, camera if camera.is_file() else None, lights if lights.is_file() else None
            )
        )
    return out


def gather(dirs: Sequence[Path] | None = None, names: Iterable[str] = ()) -> list[CorpusFrame]:
    """The frames of ``dirs`` (default: the committed subset, then :data:`OUT_DIR` when it
    exists), sorted by name; a name found in several folders is taken from the last (a full
    render rather than its packed CI copy)."""
    folders = dirs or [d for d in (CI_DIR, OUT_DIR) if d.is_dir()]
    wanted = tuple(names)
    by_name = {f.name: f for d in folders for f in find_frames(d, wanted)}
    return [by_name[k] for k in sorted(by_name)]


# -- Blender renders -----------------------------------------------------------------------------


def blender_path() -> str:
    found = shutil.which(os.environ.get("BLENDER", "blender"))
    if found is None:
        raise SystemExit(
            "corpus: blender is not installed (Debian: apt-get install blender; or set BLENDER)"
        )
    return found


#: What a frame is made of: the EXR and its two sidecars.
FRAME_SUFFIXES = (".exr", ".camera.json", ".lights.json")


def render_scene(scene: str, size: str, samples: int, out: Path, threads: int = 0) -> Path:
    """Render one frame of ``scene`` with Blender into ``out``; returns the EXR's path. Blender
    writes under a temporary name; the three files get their names once all are written, so an
    interrupted render leaves no frame behind."""
    width, height = SIZES[size]
    name = stem(scene, size, samples)
    partial = f".{name}.partial"
    cmd = [
        blender_path(),
        "-b",
        "--factory-startup",
        "--python-exit-code",
        "1",
        "--python",
        str(SCENES_DIR / f"{scene}.py"),
        "--",
        *("--out", str(out), "--name", partial),
        *("--width", str(width), "--height", str(height)),
        *("--samples", str(samples), "--threads", str(threads)),
    ]
    t0 = time.perf_counter()
    run = subprocess.run(cmd, capture_output=True, text=True, check=False)
    written = [out / (partial + suffix) for suffix in FRAME_SUFFIXES]
    if run.returncode != 0 or not all(p.is_file() for p in written):
        for p in written:
            p.unlink(missing_ok=True)
        tail = "\n".join((run.stdout + run.stderr).splitlines()[-15:])
        raise SystemExit(f"corpus: blender failed on {scene} ({run.returncode}):\n{tail}")
    for p, suffix in zip(written, FRAME_SUFFIXES, strict=True):
        p.replace(out / (name + suffix))
    exr = out / f"{name}.exr"
    print(f"wrote {exr} ({width}x{height}, {samples} spp, {time.perf_counter() - t0:.1f} s)")
    return exr


def pack(src: Path, dst: Path) -> None:
    """Rewrite Blender's float EXR ``src`` as ``dst``: every pass HALF but :data:`FLOAT_PASSES`,
    ZIP, with the header attributes and channel names as Blender wrote them."""
    import OpenEXR

    with OpenEXR.File(str(src), separate_channels=True) as exr:
        header = dict(exr.header())
        channels = {}
        for name, channel in exr.channels().items():
            pixels = np.asarray(channel.pixels)
            keep = any(f".{p}." in f".{name}" for p in FLOAT_PASSES)
            typed = pixels.astype(np.float32 if keep else np.float16)
            channels[name] = OpenEXR.Channel(np.ascontiguousarray(typed))
    header["compression"] = OpenEXR.ZIP_COMPRESSION
    tmp = dst.with_name(f".{dst.name}.tmp.exr")
    OpenEXR.File(header, channels).write(str(tmp))
    tmp.replace(dst)


def render_ci(threads: int = 0, out: Path = CI_DIR) -> None:
    """Render :data:`CI_FRAMES` and store them packed (:func:`pack`) with their sidecars."""
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for scene, size, samples in CI_FRAMES:
            exr = render_scene(scene, size, samples, Path(tmp), threads)
            pack(exr, out / exr.name)
            for suffix in (".camera.json", ".lights.json"):
                shutil.copyfile(exr.with_suffix(suffix), out / (exr.stem + suffix))
            print(f"packed {out / exr.name} ({(out / exr.name).stat().st_size // 1024} KB)")


# -- Depict's renders of meshes ------------------------------------------------------------------


def render_meshes(models: Path, sizes: Sequence[str], out: Path) -> list[Path]:
    """Depict's renders (:func:`gbuffer.render.render`, default lights) of every mesh in
    ``models`` at each size, with their lights file; nothing (and a message) when it is absent."""
    if not models.is_dir():
        print(f"corpus: no mesh folder {models}; skipping Depict's renders (pass --models DIR)")
        return []
    os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
    import gbuffer
    from bench.compare_meshes import VIEWS
    from gbuffer.render import auto_camera, default_lights, load_mesh, render

    lights = [
        ",".join(f"{v:.4f}" for v in light.vector) + ("" if k == 0 else f"*{light.intensity:g}")
        for k, light in enumerate(default_lights())
    ]
    written = []
    out.mkdir(parents=True, exist_ok=True)
    for path in sorted(p for p in models.iterdir() if p.suffix in (".obj", ".ply")):
        mesh = load_mesh(path)
        mesh.merge_vertices(merge_tex=True, merge_norm=True)
        az, el = VIEWS.get(path.stem, (30.0, 20.0))
        for size in sizes:
            width, height = SIZES[size]
            cam = auto_camera(mesh, width=width, height=height, azimuth_deg=az, elevation_deg=el)
            exr = out / f"mesh_{path.stem}_{size}.exr"
            gbuffer.write(render(mesh, width, height, camera=cam), exr)
            info = {"lights": lights, "renderer": "depict render (gbuffer.render)"}
            exr.with_suffix(".lights.json").write_text(json.dumps(info, indent=1) + "\n")
            print(f"wrote {exr}")
            written.append(exr)
    return written


# -- command line --------------------------------------------------------------------------------


def _pick(values: Sequence[str] | None, allowed: Iterable[str], what: str) -> list[str]:
    allowed = list(allowed)
    chosen = list(values or allowed)
    for v in chosen:
        if v not in allowed:
            raise SystemExit(f"corpus: unknown {what} {v!r}; choose from {', '.join(allowed)}")
    return chosen


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render Blender scenes (all sizes and samples by default)")
    r.add_argument("--size", action="append", help=f"one of {', '.join(SIZES)} (repeatable)")
    r.add_argument("--samples", action="append", type=int, help="samples per pixel (repeatable)")
    r.add_argument("--scene", action="append", help="scene name (repeatable; default: all)")
    r.add_argument("--out", type=Path, default=OUT_DIR)
    r.add_argument("--threads", type=int, default=0, help="Blender's threads (0: all cores)")
    m = sub.add_parser("meshes", help="Depict's renders of a mesh folder")
    m.add_argument("--size", action="append", help=f"one of {', '.join(SIZES)} (repeatable)")
    m.add_argument("--models", type=Path, default=DEFAULT_MODELS)
    m.add_argument("--out", type=Path, default=OUT_DIR)
    c = sub.add_parser("ci", help="re-render the committed CI subset")
    c.add_argument("--out", type=Path, default=CI_DIR)
    c.add_argument("--threads", type=int, default=0)
    ls = sub.add_parser("list", help="list the frames of a folder")
    ls.add_argument("folder", nargs="?", type=Path, default=OUT_DIR)
    args = ap.parse_args(argv)

    if args.command == "render":
        sizes = _pick(args.size, SIZES, "size")
        scenes = _pick(args.scene, scene_names(), "scene")
        samples = args.samples or list(SAMPLES)
        args.out.mkdir(parents=True, exist_ok=True)
        for size in sizes:  # cheapest first: the small frames are ready early
            for spp in sorted(samples):
                for scene in scenes:
                    render_scene(scene, size, spp, args.out, args.threads)
    elif args.command == "meshes":
        render_meshes(args.models, _pick(args.size, SIZES, "size"), args.out)
    elif args.command == "ci":
        render_ci(args.threads, args.out)
    else:
        for f in find_frames(args.folder):
            extra = [k for k in ("camera", "lights") if getattr(f, k) is not None]
            print(f"{f.exr}  ({', '.join(extra) or 'no sidecars'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
