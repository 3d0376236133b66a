""":func:`to_frame`: a file's channels mapped to a :class:`~gbuffer.frame.Frame` by a preset, in
steps (channels -> grid -> background and depth -> camera -> buffers -> normals -> positions
-> coverage -> lobes -> frame, holes and result layer); :mod:`gbuffer.presets` has the
conventions they apply."""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from gbuffer.camera import Camera
from gbuffer.colorspace import ColorSpace, resolve_leniently
from gbuffer.colorspace import resolve as resolve_colorspace
from gbuffer.errors import FrameError, OptionError
from gbuffer.exr import ExrPassthrough, release_pixels, window
from gbuffer.frame import LOBES, Frame, Passthrough
from gbuffer.holes import hole_warnings, mark_holes
from gbuffer.presets.channels import (
    ChannelReader,
    channel_list,
    check_finite,
    describe,
    find_channels,
    flat_channels,
    resolve,
    sum_into,
)
from gbuffer.presets.detect import detect
from gbuffer.presets.geometry import (
    camera_error,
    camera_from_positions,
    check_facing,
    file_camera,
    length_trust,
    pose_only_warning,
    to_camera_normals,
    to_camera_points,
)
from gbuffer.presets.options import ReadOptions, read_options
from gbuffer.presets.spec import LobeSpec, Preset
from gbuffer.presets.table import PRESETS, find_preset

#: Header attribute naming the layer of Depict's result in the files it writes ("" for R,G,B,A).
RESULT_ATTRIBUTE = "depict/result"


def to_frame(
    passthrough: Passthrough,
    preset: str | Preset = "auto",
    camera: Camera | None = None,
    overrides: ReadOptions | Mapping[str, Any] | None = None,
    *,
    release: bool = False,
) -> Frame:
    """Map a file's channels to canonical buffers (see :mod:`gbuffer.presets`).

    Parameters
    ----------
    passthrough : the file as read (:func:`gbuffer.exr.read_parts`).
    preset : a preset name, a :class:`Preset`, or ``"auto"`` (:func:`detect`).
    camera : a camera that overrides the file's (``None``: the file's, if any).
    overrides : :class:`ReadOptions` (or its dict form).
    release : let go of each channel's decoded pixels once its buffer is made
        (:func:`gbuffer.exr.release_pixels`; they are decoded again if read later), so that a
        frame written beside its input (``part`` or ``sidecar`` layout) never holds the file's
        channels and its buffers at once.

    Returns
    -------
    Frame on the primary part's data window (the part holding the beauty, else the normals,
    else the depth), with ``sources`` naming the channels of each buffer and the passthrough
    kept for writing. Its ``passthrough.warnings`` (when an :class:`ExrPassthrough`) lists
    what the user should know (dropped layers, approximations).

    Raises
    ------
    FrameError
        NaN/Inf in a data channel, a bad mapping, a UINT channel for a float buffer.
    MissingCameraError
        World-space normals and no camera (unless ``require_camera`` is False).
    """
    opts = read_options(overrides)
    build = _Build.start(passthrough, _choose_preset(passthrough, preset), opts, release)
    build.grid(camera)
    build.background_and_depth()
    build.fit_camera()
    build.planar_depth()
    build.plain_buffers()
    build.normals()
    build.positions()
    build.coverage()
    build.lobes()
    return build.frame()


def _choose_preset(passthrough: Passthrough, preset: str | Preset) -> Preset:
    """The preset named (or detected for ``"auto"``); why it was chosen goes to the file."""
    where = passthrough.path if isinstance(passthrough, ExrPassthrough) else "frame"
    if not passthrough.parts:
        raise FrameError(f"{where}: the file has no parts")
    reason = "chosen by the user"
    if preset == "auto":
        name, reason = detect(passthrough)
        chosen = PRESETS[name]
    else:
        chosen = find_preset(preset) if isinstance(preset, str) else preset
    if isinstance(passthrough, ExrPassthrough):
        passthrough.preset_reason = reason
    return chosen


@dataclass
class _Build:
    """A frame being read: the preset, the file's channels and what the steps found so far."""

    pt: Passthrough
    preset: Preset
    opts: ReadOptions
    reader: ChannelReader
    warnings: list[str]
    prefix: str = ""
    result_layer: str | None = None
    marked: str | None = None
    found: dict[str, list[str]] = field(default_factory=dict)
    lobe_found: dict[str, list[list[str]]] = field(default_factory=dict)
    spaces: dict[str, str] = field(default_factory=dict)
    buffers: dict[str, np.ndarray] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)
    camera: Camera | None = None
    camera_in_file: bool = False  # the camera is the file's (not one given)
    display_size: tuple[int, int] = (0, 0)
    origin: tuple[int, int] = (0, 0)
    background: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), bool))
    alpha: np.ndarray | None = None
    depth: np.ndarray | None = None
    position: np.ndarray | None = None
    trust: np.ndarray | None = None

    @classmethod
    def start(cls, pt: Passthrough, preset: Preset, opts: ReadOptions, release: bool) -> _Build:
        """Step 1, channels: the view layer, an earlier result of Depict, and the channels of
        every buffer the preset (or the user's mapping) names."""
        where = pt.path if isinstance(pt, ExrPassthrough) else "frame"
        warnings: list[str] = pt.warnings if isinstance(pt, ExrPassthrough) else []
        flat = flat_channels(pt.parts)
        reader = ChannelReader(pt, flat, where, strict=opts.strict, release=release)
        build = cls(pt, preset, opts, reader, warnings, prefix=opts.layer or "")
        if preset.view_layer is not None:
            build.prefix = _view_layer(flat, preset, opts, warnings)
            build.result_layer = f"{build.prefix}.Depict" if build.prefix else None
        build.marked = _marked_result(pt, flat, warnings)
        if build.marked is not None:
            build.result_layer = build.marked or None
            if "beauty" not in opts.mapping:  # an output of Depict: its result is the beauty
                mapping = {**opts.mapping, "beauty": build.marked or "R,G,B"}
                build.opts = dataclasses.replace(opts, mapping=mapping)
        build.find_buffers()
        build.find_lobes()
        build.count_uses()
        return build

    def find(self, buffer: str, layers: Sequence[str], n: int | None = None) -> list[str] | None:
        return find_channels(self.reader, buffer, layers, self.prefix, self.opts, n)

    def find_buffers(self) -> None:
        for buffer, layers in self.preset.buffers.items():
            names = self.find(buffer, layers)
            if names is not None:
                self.found[buffer] = names
        for buffer in ("normal", "position"):
            names, space = self.find_oriented(buffer)
            if names is not None:
                self.found[buffer] = names
                self.spaces[buffer] = space
        for key in ("coverage", "roughness"):
            if key in self.opts.mapping and key not in self.found:
                names = self.find(key, ())
                if names is not None:
                    self.found[key] = names

    def find_lobes(self) -> None:
        """The layers summed into each lobe's radiance, light and colour: the user's mapping,
        else the first of the preset's alternatives with any layer present (a colour: its first
        layer)."""
        for lobe in LOBES:
            spec = self.preset.lobes.get(lobe, LobeSpec())
            colors = tuple((c,) for c in spec.color)
            for key, alternatives in (
                (lobe, spec.radiance),
                (f"{lobe}.light", spec.light),
                (f"{lobe}.color", colors),
            ):
                layers = self.lobe_layers(key, alternatives)
                self.lobe_found[key] = layers[:1] if key.endswith(".color") else layers

    def lobe_layers(self, key: str, alternatives: Sequence[tuple[str, ...]]) -> list[list[str]]:
        if key in self.opts.mapping:
            names = self.find(key, (), n=3)
            return [] if names is None else [names]
        for alt in alternatives:
            layers = [names for layer in alt if (names := self.find(key, (layer,), n=3))]
            if layers:
                return layers
        return []

    def count_uses(self) -> None:
        """How many buffers each channel goes into, so that the reader can let a channel's
        pixels go after its last use (``release``), and those of no buffer at once."""
        lists = [*self.found.values()] + [n for ls in self.lobe_found.values() for n in ls]
        reader = self.reader
        reader.uses = Counter(name for names in lists for name in names)
        if reader.release:
            used = {reader.flat[name] for name in reader.uses}
            release_pixels(self.pt, sorted(set(reader.flat.values()) - used))

    def find_oriented(self, buffer: str) -> tuple[list[str] | None, str]:
        """The normals' or positions' channels and their space: the user's mapping and space,
        else the preset's first candidate found."""
        candidates = self.preset.normal if buffer == "normal" else self.preset.position
        override = self.opts.normal_space if buffer == "normal" else self.opts.position_space
        if buffer in self.opts.mapping:
            space = override or (candidates[0][1] if candidates else "camera")
            return self.find(buffer, ()), space
        for layer, space in candidates:
            names = self.find(buffer, (layer,))
            if names is not None:
                return names, override or space
        return None, ""

    def grid(self, camera: Camera | None) -> None:
        """Step 2, grid: the part that holds the beauty (else the normals, else the depth) sets
        the pixel grid; its display window places it; the camera given, else the file's."""
        primary = 0
        for key in ("beauty", "normal", "depth", "alpha"):
            if key in self.found:
                primary = self.reader.flat[self.found[key][0]][0]
                break
        self.pt.primary = primary
        self.reader.set_primary(primary)
        header = self.pt.parts[primary][0]
        grid = self.reader.grid
        dx0, dy0, dx1, dy1 = window(header, "displayWindow") if "displayWindow" in header else grid
        self.display_size = (dx1 - dx0 + 1, dy1 - dy0 + 1)
        self.origin = (grid[0] - dx0, grid[1] - dy0)
        if camera is None:  # the primary part's, else another part's (a part a tool added)
            headers = [header] + [h for i, (h, _) in enumerate(self.pt.parts) if i != primary]
            self.camera = next(
                (cam for h in headers if (cam := file_camera(h, self.warnings)) is not None), None
            )
            self.camera_in_file = self.camera is not None
        else:
            self.camera = camera if camera.source else dataclasses.replace(camera, source="given")
        self.background = np.zeros(self.reader.shape, bool)

    def background_and_depth(self) -> None:
        """Step 3, background: alpha 0, or a depth that is not finite, <= 0 or at the preset's
        background value; the depth as read."""
        reader, background = self.reader, self.background
        if "alpha" in self.found:
            names = self.found["alpha"]
            self.alpha = reader.stack(names, "alpha")
            check_finite(reader, names, self.alpha, self.alpha <= 0.0)  # (-inf: background)
            background |= self.alpha <= 0.0
            self.buffers["alpha"] = self.alpha
            self.sources["alpha"] = names[0]
        if "depth" not in self.found:
            return
        name = self.found["depth"][0]
        depth = reader.stack(self.found["depth"], "depth", fill=np.inf)
        nan = np.isnan(depth)
        if nan.any() and (nan & ~background).any():
            if not self.opts.strict:
                reader.add_holes(name, nan & ~background, radiance=False)
            else:
                ys, xs = np.nonzero(nan & ~background)
                raise FrameError(
                    f"{reader.where}: channel '{name}' has {len(ys)} NaN value(s) on covered "
                    f"pixels (first at x={xs[0]}, y={ys[0]} of the data window)"
                )
        limit = self.opts.depth_background or self.preset.depth_background
        with np.errstate(invalid="ignore"):
            background |= ~(np.isfinite(depth) & (depth > 0.0) & (depth < limit))
        self.depth = depth

    def load(self, buffer: str, names: list[str]) -> np.ndarray:
        """A buffer's channels, NaN/Inf on covered pixels refused or made holes."""
        arr = self.reader.stack(names, buffer)
        radiance = buffer in ("beauty", "albedo")
        check_finite(self.reader, names, arr, self.background, radiance=radiance)
        return arr

    def fit_camera(self) -> None:
        """Step 4, camera: world-space positions solve it when none is known, complete a pose
        without a field of view, or measure how well the known one fits them."""
        if "position" in self.found:
            self.position = self.load("position", self.found["position"])
        if self.position is not None and self.spaces["position"] == "world":
            self.camera = camera_from_positions(
                self.camera,
                self.position,
                ~self.background,
                self.display_size,
                self.origin,
                self.depth,
                self.found,
                self.warnings,
            )
        if self.camera_in_file and (lacks := pose_only_warning(self.camera)) is not None:
            self.warnings.append(lacks)

    def colorspace(self) -> ColorSpace:
        """The working space (:func:`gbuffer.colorspace.resolve`); for an inspection (not
        ``strict``), a colour attribute of the header that cannot be used is a warning."""
        header = self.pt.parts[self.pt.primary][0]
        args = (self.opts.colorspace, header, self.preset.name, self.preset.colorspace)
        if self.opts.strict:
            return resolve_colorspace(*args)
        return resolve_leniently(*args, self.warnings)

    def planar_depth(self) -> None:
        """Step 5, depth: +inf on background, a distance along the ray made planar."""
        depth = self.depth
        if depth is None:
            return
        src = self.found["depth"][0]
        depth[self.background] = np.inf
        if (self.opts.depth or self.preset.depth_kind) == "distance":
            camera = self.camera
            if camera is not None and camera.has_intrinsics:
                vz = camera.view_vectors(self.reader.shape, self.display_size, self.origin)
                depth *= vz[..., 2]
                src += " (distance along the ray -> planar)"
            else:
                self.warnings.append(
                    f"depth {src} is the distance along the ray and no camera field of view is "
                    "known: used as planar depth (pass a camera to convert)"
                )
        self.buffers["depth"] = depth
        self.sources["depth"] = src

    def plain_buffers(self) -> None:
        """Step 6: the beauty, albedo, AO and roughness, as they are."""
        for key in ("beauty", "albedo", "ao", "roughness"):
            if key in self.found:
                self.buffers[key] = self.load(key, self.found[key])
                self.sources[key] = describe(self.found[key])

    def normals(self) -> None:
        """Step 7, normals: decoded, to camera space, renormalised; their length is the trust
        of the coverage formula."""
        if "normal" not in self.found:
            return
        names, space = self.found["normal"], self.spaces["normal"]
        src = describe(names)
        n = self.load("normal", names)
        if self.opts.normal_encoding == "unsigned":
            n = n * np.float32(2.0) - np.float32(1.0)
        camera = self.camera
        if space == "world" and (camera is None or camera.world_to_camera is None):
            if self.opts.require_camera:
                raise camera_error(self.reader.where, "normals", src, camera)
            self.warnings.append(f"normals {src} left out: world space and no camera")
            return
        n = to_camera_normals(n, space, camera)
        with np.errstate(over="ignore"):  # (a component past 1.8e19: its length is inf)
            length = np.sqrt(cv2.transform(n * n, np.ones((1, 3), np.float32)))
        length = np.asarray(length, np.float32).reshape(self.reader.shape)
        empty = length < 1e-6
        # one pass: n * (1 / |n|), 0 where empty or background
        inv = np.zeros_like(length)
        np.divide(np.float32(1.0), length, out=inv, where=~(empty | self.background))
        n *= inv[..., None]
        self.trust = length_trust(length, self.opts.normal_tolerance)
        self.trust[empty] = 0.0
        self.buffers["normal"] = n
        self.sources["normal"] = src + (f" ({space} -> camera)" if space != "camera" else "")
        if space == "world":
            shape = self.reader.shape
            check_facing(n, camera, shape, self.display_size, self.origin, src, self.warnings)

    def positions(self) -> None:
        """Step 8, positions: to camera space (0 on background); the depth when none was read."""
        if self.position is None:
            return
        names, space = self.found["position"], self.spaces["position"]
        src = describe(names)
        camera = self.camera
        if space == "world" and (camera is None or camera.world_to_camera is None):
            self.warnings.append(f"position {src} left out: world space and no camera")
            return
        pos = to_camera_points(self.position, space, camera)
        pos[self.background] = 0.0
        self.buffers["position"] = pos
        self.sources["position"] = src + (f" ({space} -> camera)" if space != "camera" else "")
        if "depth" not in self.buffers:
            d = -pos[..., 2].copy()
            d[self.background | ~(d > 0)] = np.inf
            self.buffers["depth"] = d
            self.sources["depth"] = f"-z of position {src}"

    def coverage(self) -> None:
        """Step 9, coverage: the file's own, else min(alpha, trust of the normal length); 0 on
        background."""
        if "coverage" in self.found:
            cov = np.clip(self.load("coverage", self.found["coverage"]), 0.0, 1.0)
            self.sources["coverage"] = describe(self.found["coverage"])
        elif self.trust is not None or self.alpha is not None or self.depth is not None:
            parts = []
            cov = np.ones(self.reader.shape, np.float32)
            if self.alpha is not None:
                parts.append("alpha")
                np.minimum(cov, np.clip(self.alpha, 0.0, 1.0), out=cov)
            if self.trust is not None:
                parts.append("normal length")
                np.minimum(cov, self.trust, out=cov)
            self.sources["coverage"] = f"min({', '.join(parts)})" if parts else "finite depth"
        else:
            return
        cov = cov.astype(np.float32, copy=False)
        if self.background.any():
            cov[self.background] = 0.0
        self.buffers["coverage"] = cov

    def lobes(self) -> None:
        """Step 10, lobes: radiance, light and colour of each lobe (the missing one derived),
        and the remainder = beauty minus their sum."""
        lobe_sum = None
        for lobe in LOBES:
            rad = self.lobe(lobe)
            if rad is not None:
                lobe_sum = rad.copy() if lobe_sum is None else cv2.add(lobe_sum, rad, dst=lobe_sum)
        if lobe_sum is not None and "beauty" in self.buffers:  # beauty - sum, in the sum's place
            remainder = cv2.subtract(self.buffers["beauty"], lobe_sum, dst=lobe_sum)
            self.buffers["remainder"] = remainder
            present = [lobe for lobe in LOBES if lobe in self.buffers]
            self.sources["remainder"] = "beauty - (" + " + ".join(present) + ")"

    def lobe(self, lobe: str) -> np.ndarray | None:
        """One lobe's buffers; its radiance, or None."""
        src: dict[str, str] = {}
        rad = self.lobe_part(lobe, src)
        light = self.lobe_part(f"{lobe}.light", src)
        color = self.lobe_part(f"{lobe}.color", src)
        if rad is None and light is not None and color is not None:
            rad = light * color
            src[lobe] = f"({src[lobe + '.light']}) * {src[lobe + '.color']}"
        if rad is not None and light is None and color is not None:
            safe = np.where(color > 1e-6, color, np.float32(1.0))
            light = np.where(color > 1e-6, rad / safe, np.float32(0.0)).astype(np.float32)
            src[lobe + ".light"] = f"{src[lobe]} / {src[lobe + '.color']}"
        for key, arr in ((lobe, rad), (f"{lobe}.light", light), (f"{lobe}.color", color)):
            if arr is not None:
                self.buffers[key] = arr
                self.sources[key] = src[key]
        if rad is None and (light is not None or color is not None):
            self.warnings.append(f"{lobe}: light or colour found without the other; no {lobe} lobe")
        return rad

    def lobe_part(self, key: str, sources: dict[str, str]) -> np.ndarray | None:
        """Sum of the layers :meth:`find_lobes` found for ``key`` (3 components)."""
        layers = self.lobe_found.get(key, [])
        if not layers:
            return None
        total = [self.load_radiance(key, names) for names in layers]
        sources[key] = " + ".join(describe(n) for n in layers)
        return sum_into(total)

    def load_radiance(self, key: str, names: list[str]) -> np.ndarray:
        arr = self.reader.stack(names, key)
        check_finite(self.reader, names, arr, self.background, radiance=True)
        return arr

    def frame(self) -> Frame:
        """Step 11: the frame, its holes (NaN/Inf radiance) and the warnings that go with it."""
        if not self.buffers:
            self.warnings.append(
                "no buffer recognised with preset "
                f"'{self.preset.name}'; channels: {channel_list(self.reader.flat)} "
                "(choose --preset or --map)"
            )
        if self.marked is not None and "beauty" in self.sources:
            self.sources["beauty"] += " (Depict's result: depict/result)"
        frame = Frame(
            buffers=self.buffers,
            camera=self.camera,
            display_size=self.display_size,
            origin=self.origin,
            preset=self.preset.name,
            sources=self.sources,
            passthrough=self.pt,
            result_layer=self.result_layer,
            colorspace=self.colorspace(),
        )
        reader = self.reader
        if reader.holes is not None:
            beauty = self.found.get("beauty")
            original = reader.stack(beauty, "beauty") if beauty is not None else None
            notes = mark_holes(frame, reader.holes, original)
            self.warnings += hole_warnings(reader.hole_channels, reader.masked_channels, notes)
        return frame


def _view_layer(
    flat: Mapping[str, Any], preset: Preset, opts: ReadOptions, warnings: list[str]
) -> str:
    """The view layer whose passes are read (Blender): the user's, else the one with the most
    passes (not the "Composite" layer, Combined alone, that Blender adds to a render saved with
    the compositor on)."""
    passes = preset.view_layer
    assert passes is not None
    prefixes: list[str] = []
    for name in flat:
        layer = passes.view_layer(name)
        if layer is not None and layer not in prefixes:
            prefixes.append(layer)
    if opts.layer is not None:
        if opts.layer not in prefixes and prefixes:  # (the request, not the file, is wrong)
            raise OptionError(
                f"view layer '{opts.layer}' not in the file; layers: {', '.join(prefixes)}"
            )
        return opts.layer
    if not prefixes:
        return ""
    counts = {
        p: sum(1 for n in flat if n.startswith(f"{p}.") and passes.view_layer(n) is not None)
        for p in prefixes
    }
    beauty = preset.buffers["beauty"][0]
    chosen = max(prefixes, key=lambda p: (counts[p], f"{p}.{beauty}.R" in flat))
    if len(prefixes) > 1:
        warnings.append(
            f"view layers {', '.join(prefixes)}: using '{chosen}' (choose with --view-layer "
            "NAME, the view_layer form field over HTTP)"
        )
    return chosen


def _marked_result(pt: Passthrough, flat: Mapping[str, Any], warnings: list[str]) -> str | None:
    """The layer of an earlier Depict result (``depict/result``; "" for R,G,B,A), if the file
    has one whose channels are all there."""
    for header, _ in pt.parts:
        layer = header.get(RESULT_ATTRIBUTE)
        if isinstance(layer, str):
            if resolve(flat, layer, 3) is not None:
                return layer
            warnings.append(f"{RESULT_ATTRIBUTE}={layer!r} names no RGB layer of the file")
    return None
