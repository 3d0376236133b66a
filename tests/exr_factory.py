"""Test EXR files in each renderer's layout, written with the OpenEXR binding (or by hand).

:func:`make_scene` ray-casts a sphere in front of a camera (2x2 supersampling for the filtered
passes, one centre sample for depth and position, as renderers do) and shades it with known
lobes, so every buffer a preset produces has an exact expected value. The ``write_*``
functions store that scene under each renderer's channel names and conventions (world or
camera space, planar depth or distance, background sentinels, header signatures).
:func:`write_raw_exr` builds an uncompressed scanline file byte by byte, for what the binding
cannot write (double attributes, bad pixel types, ...).
"""

from __future__ import annotations

import dataclasses
import io
import math
import struct
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR

from gbuffer.camera import Camera

BLENDER_BG = 1e10
ARNOLD_BG = 1e12


@dataclass
class Scene:
    """Expected canonical buffers (camera space, float32) and the camera."""

    camera: Camera
    alpha: np.ndarray
    normal: np.ndarray  # unit, camera space, 0 on background
    normal_filtered: np.ndarray  # 2x2 average of unit normals (shorter at edges)
    depth: np.ndarray  # planar, +inf on background
    distance: np.ndarray  # along the ray, +inf on background
    position: np.ndarray  # camera space, 0 on background
    albedo: np.ndarray
    diffuse_light: np.ndarray
    specular_light: np.ndarray
    specular_color: np.ndarray
    transmission_light: np.ndarray
    transmission_color: np.ndarray
    emission: np.ndarray
    ao: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.alpha.shape[0]), int(self.alpha.shape[1]))

    @property
    def diffuse(self) -> np.ndarray:
        return self.diffuse_light * self.albedo

    @property
    def specular(self) -> np.ndarray:
        return self.specular_light * self.specular_color

    @property
    def transmission(self) -> np.ndarray:
        return self.transmission_light * self.transmission_color

    @property
    def beauty(self) -> np.ndarray:
        return (self.diffuse + self.specular + self.transmission + self.emission).astype(np.float32)

    @property
    def covered(self) -> np.ndarray:
        return np.isfinite(self.depth)

    @property
    def world_to_camera(self) -> np.ndarray:
        assert self.camera.world_to_camera is not None
        return self.camera.world_to_camera

    def to_world_vectors(self, v: np.ndarray) -> np.ndarray:
        rot = self.world_to_camera[:3, :3]
        return (v @ rot).astype(np.float32)  # R^T v for row vectors

    def to_world_points(self, p: np.ndarray) -> np.ndarray:
        c2w = np.linalg.inv(self.world_to_camera)
        out = p @ c2w[:3, :3].T + c2w[:3, 3]
        out[~self.covered] = 0.0
        return out.astype(np.float32)


def look_at(eye: tuple[float, float, float], target: tuple[float, float, float]) -> np.ndarray:
    """World-to-camera (OpenGL: the camera looks down -z, +y up), world Z up."""
    e, t = np.asarray(eye, float), np.asarray(target, float)
    back = e - t
    back /= np.linalg.norm(back)
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = right, up, back
    m[:3, 3] = -m[:3, :3] @ e
    return m


def make_scene(h: int = 48, w: int = 64, fov_y_deg: float = 40.0, radius: float = 1.0) -> Scene:
    """A sphere of ``radius`` at 4 units in front of a camera placed off-axis in the world."""
    w2c = look_at((3.0, -2.5, 1.5), (0.2, 0.1, 0.3))
    camera = Camera(world_to_camera=w2c, fov_y_deg=fov_y_deg)
    f = 0.5 * h / math.tan(math.radians(fov_y_deg) / 2.0)
    centre = np.array([0.25, -0.1, -4.0])

    def cast(ss: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        xs = (np.arange(w * ss) + 0.5) / ss - w / 2.0
        ys = (np.arange(h * ss) + 0.5) / ss - h / 2.0
        d = np.stack(np.broadcast_arrays(xs[None, :] / f, -ys[:, None] / f, -1.0), -1)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        b = d @ centre
        disc = b * b - (centre @ centre - radius * radius)
        hit = disc >= 0
        t = np.where(hit, b - np.sqrt(np.maximum(disc, 0)), np.inf)
        p = d * np.where(hit, t, 0.0)[..., None]
        n = np.where(hit[..., None], (p - centre) / radius, 0.0)
        return hit, p, n

    hit, p, n = cast(1)
    hit2, _, n2 = cast(2)
    alpha = hit2.reshape(h, 2, w, 2).mean(axis=(1, 3))
    n_filtered = n2.reshape(h, 2, w, 2, 3).mean(axis=(1, 3))
    depth = np.where(hit, -p[..., 2], np.inf)
    distance = np.where(hit, np.linalg.norm(p, axis=-1), np.inf)
    light = np.array([0.4, 0.7, 0.6])
    light /= np.linalg.norm(light)
    ndl = np.clip(n @ light, 0, None)
    view = -p / np.maximum(np.linalg.norm(p, axis=-1, keepdims=True), 1e-9)
    half = light + view
    half /= np.maximum(np.linalg.norm(half, axis=-1, keepdims=True), 1e-9)
    spec = np.clip(np.sum(n * half, axis=-1), 0, None) ** 20
    u = np.linspace(0, 1, w)[None, :, None]
    v = np.linspace(0, 1, h)[:, None, None]
    albedo = np.concatenate(np.broadcast_arrays(0.2 + 0.6 * u, 0.5 + 0 * u, 0.8 - 0.5 * v), -1)
    cov = hit[..., None]
    f32 = np.float32

    def rgb(x: np.ndarray) -> np.ndarray:
        return np.where(cov, np.broadcast_to(x, (h, w, 3)), 0.0).astype(f32)

    return Scene(
        camera=camera,
        alpha=alpha.astype(f32),
        normal=n.astype(f32),
        normal_filtered=n_filtered.astype(f32),
        depth=depth.astype(f32),
        distance=distance.astype(f32),
        position=np.where(cov, p, 0.0).astype(f32),
        albedo=rgb(albedo),
        diffuse_light=rgb((2.0 * ndl + 0.15)[..., None] * np.array([1.0, 0.95, 0.9])),
        specular_light=rgb(3.0 * spec[..., None] * np.ones(3)),
        specular_color=rgb(np.array([0.04, 0.04, 0.04])),
        transmission_light=rgb(0.3 * (1 - ndl)[..., None] * np.ones(3)),
        transmission_color=rgb(np.array([0.1, 0.2, 0.3])),
        emission=rgb(np.array([0.05, 0.0, 0.02])),
        ao=np.where(hit, 0.5 + 0.5 * n[..., 2], 0.0).astype(f32),
    )


def cropped(s: Scene, rows: slice, cols: slice) -> Scene:
    """The scene's pixels in ``rows`` and ``cols`` (its camera as it is)."""
    arrays = {f.name: getattr(s, f.name) for f in dataclasses.fields(s)}
    return dataclasses.replace(
        s, **{k: a[rows, cols] for k, a in arrays.items() if isinstance(a, np.ndarray)}
    )


def _split(arr: np.ndarray, names: tuple[str, ...], prefix: str, dtype: Any) -> dict[str, Any]:
    out = {}
    for k, s in enumerate(names):
        name = f"{prefix}.{s}" if prefix else s
        out[name] = np.ascontiguousarray(arr[..., k] if arr.ndim == 3 else arr, dtype=dtype)
    return out


RGB = ("R", "G", "B")
XYZ = ("X", "Y", "Z")
HALF = np.float16
FLOAT = np.float32


def write_exr(path: Path, header: dict[str, Any], channels: dict[str, np.ndarray]) -> Path:
    OpenEXR.File(dict(header), dict(channels)).write(str(path))
    return path


BLENDER5_NAMES = {
    "DiffDir": "Diffuse Direct",
    "DiffInd": "Diffuse Indirect",
    "DiffCol": "Diffuse Color",
    "GlossDir": "Glossy Direct",
    "GlossInd": "Glossy Indirect",
    "GlossCol": "Glossy Color",
    "TransDir": "Transmission Direct",
    "TransInd": "Transmission Indirect",
    "TransCol": "Transmission Color",
    "AO": "Ambient Occlusion",
    "Emit": "Emission",
}


def write_blender(
    path: Path,
    s: Scene,
    layer: str = "ViewLayer",
    blender5: bool = False,
    signature: bool = True,
    position: bool = True,
) -> Path:
    """Cycles multilayer: world normals (filtered, not unit at edges), planar depth 1e10 bg,
    world positions (unless ``position`` is False)."""
    names = BLENDER5_NAMES if blender5 else {k: k for k in BLENDER5_NAMES}
    ch: dict[str, np.ndarray] = {}
    L = layer
    ch.update(_split(s.beauty, RGB, f"{L}.Combined", HALF))
    ch[f"{L}.Combined.A"] = s.alpha.astype(HALF)
    ch[f"{L}.Depth.Z"] = np.where(s.covered, s.depth, BLENDER_BG).astype(FLOAT)
    ch.update(_split(s.to_world_vectors(s.normal_filtered), XYZ, f"{L}.Normal", FLOAT))
    if position:
        ch.update(_split(s.to_world_points(s.position), XYZ, f"{L}.Position", FLOAT))
    direct = s.diffuse_light * 0.75
    ch.update(_split(direct, RGB, f"{L}.{names['DiffDir']}", FLOAT))
    ch.update(_split(s.diffuse_light - direct, RGB, f"{L}.{names['DiffInd']}", FLOAT))
    ch.update(_split(s.albedo, RGB, f"{L}.{names['DiffCol']}", FLOAT))
    ch.update(_split(s.specular_light, RGB, f"{L}.{names['GlossDir']}", FLOAT))
    ch.update(_split(s.specular_light * 0, RGB, f"{L}.{names['GlossInd']}", FLOAT))
    ch.update(_split(s.specular_color, RGB, f"{L}.{names['GlossCol']}", FLOAT))
    ch.update(_split(s.transmission_light, RGB, f"{L}.{names['TransDir']}", FLOAT))
    ch.update(_split(s.transmission_light * 0, RGB, f"{L}.{names['TransInd']}", FLOAT))
    ch.update(_split(s.transmission_color, RGB, f"{L}.{names['TransCol']}", FLOAT))
    ao = np.repeat(s.ao[..., None], 3, axis=2)
    ch.update(_split(ao, RGB, f"{L}.{names['AO']}", HALF))
    ch.update(_split(s.emission, RGB, f"{L}.{names['Emit']}", HALF))
    header: dict[str, Any] = {"compression": OpenEXR.ZIP_COMPRESSION}
    if signature:
        header["BlenderMultiChannel"] = "Blender V2.55.1 and newer"
        header["cycles.ViewLayer.samples"] = "16"
    return write_exr(path, header, ch)


def write_arnold(path: Path, s: Scene, signature: bool = True) -> Path:
    """Arnold driver_exr: R,G,B,A; N, P world; Z = distance along the ray (AI_BIG bg)."""
    ch: dict[str, np.ndarray] = {}
    ch.update(_split(s.beauty, RGB, "", HALF))
    ch["A"] = s.alpha.astype(HALF)
    ch.update(_split(s.to_world_vectors(s.normal), XYZ, "N", FLOAT))
    ch.update(_split(s.to_world_points(s.position), XYZ, "P", FLOAT))
    ch["Z"] = np.where(s.covered, s.distance, ARNOLD_BG).astype(FLOAT)
    ch.update(_split(s.diffuse * 0.6, RGB, "diffuse_direct", HALF))
    ch.update(_split(s.diffuse * 0.4, RGB, "diffuse_indirect", HALF))
    ch.update(_split(s.albedo, RGB, "diffuse_albedo", HALF))
    ch.update(_split(s.specular, RGB, "specular_direct", FLOAT))
    ch.update(_split(s.specular * 0, RGB, "specular_indirect", FLOAT))
    ch.update(_split(s.specular_color, RGB, "specular_albedo", HALF))
    ch.update(_split(s.transmission, RGB, "transmission_direct", FLOAT))
    ch.update(_split(s.transmission_color, RGB, "transmission_albedo", HALF))
    ch.update(_split(s.emission, RGB, "emission", HALF))
    header: dict[str, Any] = {"compression": OpenEXR.ZIP_COMPRESSION}
    header.update(s.camera.to_header((s.shape[1], s.shape[0])))
    for key in [k for k in header if k.startswith("depict/")]:
        del header[key]  # Arnold writes only the standard matrices
    if signature:
        header["arnold/version"] = "Arnold 7.2.1.0"
    return write_exr(path, header, ch)


def write_vray(path: Path, s: Scene, signature: bool = True) -> Path:
    """V-Ray: VRayNormals camera space, raw Z planar, VRayZDepth remapped 0-1, cameraTransform."""
    h, w = s.shape
    ch: dict[str, np.ndarray] = {}
    ch.update(_split(s.beauty, RGB, "", HALF))
    ch["A"] = s.alpha.astype(HALF)
    ch.update(_split(s.normal, XYZ, "VRayNormals", FLOAT))
    ch["Z"] = np.where(s.covered, s.depth, 1e10).astype(FLOAT)
    zd = np.where(s.covered, 1.0 - (s.depth - 3.0) / 2.0, 0.0)
    ch.update(_split(np.repeat(zd[..., None], 3, 2), RGB, "VRayZDepth", HALF))
    ch.update(_split(s.albedo, RGB, "VRayDiffuseFilter", HALF))
    ch.update(_split(s.diffuse * 0.7, RGB, "VRayLighting", HALF))
    ch.update(_split(s.diffuse * 0.3, RGB, "VRayGlobalIllumination", HALF))
    ch.update(_split(s.diffuse_light * 0.7, RGB, "VRayRawLighting", FLOAT))
    ch.update(_split(s.diffuse_light * 0.3, RGB, "VRayRawGlobalIllumination", FLOAT))
    ch.update(_split(s.specular, RGB, "VRayReflection", FLOAT))
    ch.update(_split(s.specular_color, RGB, "VRayReflectionFilter", HALF))
    ch.update(_split(s.transmission, RGB, "VRayRefraction", FLOAT))
    ch.update(_split(s.transmission_color, RGB, "VRayRefractionFilter", HALF))
    ch.update(_split(s.emission, RGB, "VRaySelfIllumination", HALF))
    c2w = np.linalg.inv(s.world_to_camera)
    assert s.camera.fov_y_deg is not None
    hfov = 2 * math.degrees(math.atan(math.tan(math.radians(s.camera.fov_y_deg) / 2) * w / h))
    header: dict[str, Any] = {
        "compression": OpenEXR.PIZ_COMPRESSION,
        # row vectors, as V-Ray writes it (C order: the binding ignores strides)
        "cameraTransform": np.ascontiguousarray(c2w.T, dtype=np.float32),
        "cameraFov": float(hfov),
    }
    if signature:
        header["vrayInfo/camera"] = "VRayCam001"
    return write_exr(path, header, ch)


def write_renderman(path: Path, s: Scene, signature: bool = True) -> Path:
    """RenderMan: Nn camera space left-handed (+z forward), z planar, __Pworld/__Nworld."""
    lh = np.array([1.0, 1.0, -1.0], np.float32)
    ch: dict[str, np.ndarray] = {}
    ch.update(_split(s.beauty, RGB, "", HALF))
    ch["A"] = s.alpha.astype(HALF)
    ch.update(_split(s.normal * lh, ("x", "y", "z"), "Nn", FLOAT))
    ch.update(_split(s.to_world_vectors(s.normal), ("r", "g", "b"), "__Nworld", FLOAT))
    ch.update(_split(s.to_world_points(s.position), ("r", "g", "b"), "__Pworld", FLOAT))
    ch["z"] = np.where(s.covered, s.depth, 1e30).astype(FLOAT)
    ch.update(_split(s.diffuse * 0.5, RGB, "directDiffuse", HALF))
    ch.update(_split(s.diffuse * 0.5, RGB, "indirectDiffuse", HALF))
    ch.update(_split(s.specular, RGB, "directSpecular", FLOAT))
    ch.update(_split(s.transmission, RGB, "transmissive", FLOAT))
    ch.update(_split(s.albedo, RGB, "albedo", HALF))
    header: dict[str, Any] = {"compression": OpenEXR.ZIP_COMPRESSION}
    if signature:
        header["Software"] = "RenderMan 26.1"
    return write_exr(path, header, ch)


def write_karma(path: Path, s: Scene) -> Path:
    """Karma/Houdini: one part per render var, bare channel names, N and P world space."""

    def part(name: str, chans: dict[str, np.ndarray], comp: Any) -> Any:
        return OpenEXR.Part({"compression": comp}, chans, name)

    parts = [
        part(
            "C",
            {**_split(s.beauty, RGB, "", HALF), "A": s.alpha.astype(HALF)},
            OpenEXR.DWAA_COMPRESSION,
        ),
        part("N", _split(s.to_world_vectors(s.normal), XYZ, "", FLOAT), OpenEXR.ZIP_COMPRESSION),
        part("P", _split(s.to_world_points(s.position), XYZ, "", FLOAT), OpenEXR.ZIP_COMPRESSION),
        part(
            "depth",
            {"Z": np.where(s.covered, s.depth, 1e30).astype(FLOAT)},
            OpenEXR.ZIP_COMPRESSION,
        ),
        part("directdiffuse", _split(s.diffuse, RGB, "", HALF), OpenEXR.PIZ_COMPRESSION),
        part("albedo", _split(s.albedo, RGB, "", HALF), OpenEXR.PIZ_COMPRESSION),
    ]
    OpenEXR.File(parts).write(str(path))
    return path


def canonical_channels(s: Scene) -> dict[str, np.ndarray]:
    ch: dict[str, np.ndarray] = {}
    ch.update(_split(s.beauty, RGB, "", HALF))
    ch["A"] = s.alpha.astype(HALF)
    ch.update(_split(s.normal, XYZ, "N", FLOAT))
    ch["depth.Z"] = s.depth.astype(FLOAT)
    ch.update(_split(s.position, XYZ, "P", FLOAT))
    ch.update(_split(s.albedo, RGB, "albedo", HALF))
    ch.update(_split(s.diffuse, RGB, "diffuse", HALF))
    ch.update(_split(s.diffuse_light, RGB, "diffuse.light", HALF))
    ch.update(_split(s.albedo, RGB, "diffuse.color", HALF))
    ch.update(_split(s.specular, RGB, "specular", FLOAT))
    ch["AO.X"] = s.ao.astype(FLOAT)
    return ch


def write_canonical(path: Path, s: Scene, header: dict[str, Any] | None = None) -> Path:
    hdr: dict[str, Any] = {"compression": OpenEXR.ZIP_COMPRESSION}
    hdr.update(s.camera.to_header((s.shape[1], s.shape[0])))
    hdr.update(header or {})
    return write_exr(path, hdr, canonical_channels(s))


def rich_header() -> dict[str, Any]:
    """Custom attributes of many types (what a compositing step must keep)."""
    tc = OpenEXR.TimeCode()
    tc.hours, tc.minutes, tc.seconds, tc.frame = 1, 2, 3, 4
    return {
        "comment": "made by exr_factory",
        "owner": "depict tests",
        "studio/shot": "sq010_sh0020",
        "myInt": 42,
        "myFloat": 0.5,
        "myV2f": np.array([1.5, -2.0], np.float32),
        "myV3i": np.array([1, 2, 3], np.int32),
        "myM33d": np.arange(9, dtype=np.float64).reshape(3, 3),
        "worldToCamera": np.arange(16, dtype=np.float32).reshape(4, 4),
        "myBox": (np.array([0.0, 0.0], np.float32), np.array([1.0, 2.0], np.float32)),
        "tags": ["a", "b", "c"],
        "weights": [0.25, 0.75],
        "framesPerSecond": Fraction(24000, 1001),
        "timeCode": tc,
        "chromaticities": (0.64, 0.33, 0.3, 0.6, 0.15, 0.06, 0.3127, 0.329),
        "pixelAspectRatio": 1.25,
        "screenWindowCenter": np.array([0.1, 0.2], np.float32),
        "screenWindowWidth": 1.5,
    }


# -- byte-level files ---------------------------------------------------------------------------


def raw_attribute(name: str, type_name: str, data: bytes) -> bytes:
    return name.encode() + b"\0" + type_name.encode() + b"\0" + struct.pack("<i", len(data)) + data


def write_raw_exr(
    path: Path,
    channels: dict[str, np.ndarray],
    extra: tuple[tuple[str, str, bytes], ...] = (),
    pixel_types: dict[str, int] | None = None,
) -> Path:
    """An uncompressed single-part scanline EXR written byte by byte (no library).

    ``extra`` adds attributes as (name, type name, value bytes); ``pixel_types`` overrides the
    pixel type code written in the channel list (to make invalid files).
    """
    names = sorted(channels)
    arrays = {n: np.ascontiguousarray(channels[n]) for n in names}
    h, w = arrays[names[0]].shape
    codes = {np.dtype(np.uint32): 0, np.dtype(np.float16): 1, np.dtype(np.float32): 2}
    chlist = b""
    for n in names:
        code = (pixel_types or {}).get(n, codes[arrays[n].dtype])
        chlist += n.encode() + b"\0" + struct.pack("<iB3xii", code, 0, 1, 1)
    head = raw_attribute("channels", "chlist", chlist + b"\0")
    head += raw_attribute("compression", "compression", b"\0")
    head += raw_attribute("dataWindow", "box2i", struct.pack("<4i", 0, 0, w - 1, h - 1))
    head += raw_attribute("displayWindow", "box2i", struct.pack("<4i", 0, 0, w - 1, h - 1))
    head += raw_attribute("lineOrder", "lineOrder", b"\0")
    head += raw_attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0))
    head += raw_attribute("screenWindowCenter", "v2f", struct.pack("<2f", 0.0, 0.0))
    head += raw_attribute("screenWindowWidth", "float", struct.pack("<f", 1.0))
    for name, type_name, data in extra:
        head += raw_attribute(name, type_name, data)
    start = b"\x76\x2f\x31\x01" + struct.pack("<I", 2) + head + b"\0"
    pos = len(start) + 8 * h
    offsets, chunks = [], []
    for y in range(h):
        data = b"".join(arrays[n][y].tobytes() for n in names)
        offsets.append(pos)
        chunks.append(struct.pack("<ii", y, len(data)) + data)
        pos += len(chunks[-1])
    path.write_bytes(start + struct.pack(f"<{h}Q", *offsets) + b"".join(chunks))
    return path


def patch_data_window(path: Path, window: tuple[int, int, int, int]) -> Path:
    """Overwrite the (first) dataWindow value in place: same size, so offsets stay valid."""
    data = bytearray(path.read_bytes())
    key = b"dataWindow\0box2i\0" + struct.pack("<i", 16)
    at = data.index(key) + len(key)
    data[at : at + 16] = struct.pack("<4i", *window)
    path.write_bytes(bytes(data))
    return path


def write_decode_bomb(path: Path, channels: int = 83, size: int = 2000) -> Path:
    """A real ZIP-compressed EXR of ``channels`` float channels of ``size`` x ``size`` zeros:
    about 1.3 MB on disk for 83 x 2000 x 2000 (1.3 GB once decoded).

    The library encodes one 16-line chunk of zeros; the file repeats that chunk (with each
    chunk's own first line) down the whole image, so it is valid and decodable.
    """
    from gbuffer.exr import layout as exr_layout
    from gbuffer.exr import write as exr_write

    assert size % 16 == 0, "whole chunks only"
    names = [f"L{i:03d}.X" for i in range(channels)]
    strip = {n: np.zeros((16, size), np.float32) for n in names}
    probe = path.with_suffix(".strip.exr")
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION}, strip).write(str(probe))
    data = probe.read_bytes()
    probe.unlink()
    layout = exr_layout._read_layout(io.BytesIO(data), len(data), str(path))
    exr_layout._read_offsets(io.BytesIO(data), layout, str(path))
    (chunk,) = exr_write._extract_chunks(io.BytesIO(data), layout, 0)
    attrs = dict(layout.parts[0].attributes)
    window = struct.pack("<4i", 0, 0, size - 1, size - 1)
    attrs["dataWindow"] = exr_layout.RawAttribute("box2i", window)
    attrs["displayWindow"] = exr_layout.RawAttribute("box2i", window)
    count = (size + 15) // 16
    chunks = [struct.pack("<i", 16 * k) + bytes(chunk[4:]) for k in range(count)]
    order = list(range(count))
    with open(path, "wb") as f:
        exr_write._assemble(f, [attrs], [chunks], [order], ["scanlineimage"], False)
    return path


def write_corrupt(path: Path) -> Path:
    """A ZIP EXR whose last compressed chunk bytes are flipped: the header reads, the pixels
    do not decode. (Smooth data, so the chunks are really compressed: incompressible chunks are
    stored raw, and EXR has no checksum to notice a corruption of those.)"""
    ramp = np.tile(np.linspace(0, 1, 64, dtype=np.float32), (64, 1))
    smooth = path.with_suffix(".smooth.exr")
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION}, {"R": ramp, "G": ramp}).write(
        str(smooth)
    )
    data = bytearray(smooth.read_bytes())
    smooth.unlink()
    for i in range(len(data) - 200, len(data) - 8):
        data[i] ^= 0x5A
    path.write_bytes(bytes(data))
    return path


def render_with_nan(path: Path, size: tuple[int, int], pixels: dict[str, list[tuple]]) -> Path:
    """A canonical render with NaN/Inf put at ``pixels``: buffer -> [(y, x, component, value)]."""
    import trimesh

    from gbuffer.io import write
    from gbuffer.render import render

    frame = render(trimesh.creation.icosphere(subdivisions=3), *size)
    for name, changes in pixels.items():
        arr = frame.buffers[name].copy()
        for y, x, k, value in changes:
            arr[y, x, k] = value
        frame.buffers[name] = arr
    frame.outputs = {}  # written from the buffers
    write(frame, path)
    return path


#: An OBJ mesh of 3 triangles, one with a NaN vertex (left out when it is read).
TORN_MESH = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv nan 2 0\nf 1 2 3\nf 2 4 3\nf 3 4 5\n"
