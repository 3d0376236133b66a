"""Screen-space ambient occlusion from planar depth and camera-space normals.

Method: normal-oriented horizon-based AO, after HBAO (Bavoil, Sainz & Dimitrov, "Image-space
horizon-based ambient occlusion", SIGGRAPH 2008 talk). For each pixel p with position P and
normal n, and for each of D image-space directions, the screen is marched over S steps up to the
projection of a radius R given in scene units. Each sample's camera-space position S_j gives
w = S_j − P and its elevation above the tangent plane, sin h_j = n·w / |w|. Marching outwards,
the occlusion of a direction grows each time the horizon rises:

    AO_dir = Σ_j W(|w_j|) · max(0, sin h_j − max(sin t, sin h_0..j−1)),   W(d) = max(0, 1 − d²/R²)

with sin t a small bias angle (hides tessellation); samples farther than R (and background)
neither occlude nor raise the horizon, so silhouettes over distant surfaces cast no halo. The
result is AO = 1 − (1/D) Σ_dir AO_dir / (1 − sin t), in [0, 1], 1 = unoccluded; as in HBAO it
is not cosine-weighted. Directions are rotated and steps jittered per pixel with a 4×4
interleaved (Bayer) pattern, and the result is smoothed by a 4×4 coverage-normalised box blur
that removes the pattern (it does not stop at depth discontinuities between two surfaces, a
4-pixel effect). A plane gives exactly 1; a concave corner is darker than its flat sides.

Everything is vectorised: only covered pixels are marched, gathered into chunks of 16k pixels
(cache-sized, optionally spread over threads); each sample is one ``cv2.remap`` (nearest) of the
depth buffer with a per-pixel offset (the radius in pixels is R·f / depth, perspective, or
R / pixel size, orthographic), from which the sample's position is rebuilt exactly.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import cv2
import numpy as np

__all__ = ["ssao"]

_FAR = np.float32(1e18)  # finite stand-in for background depth (d² stays finite in float32)

#: 4×4 Bayer order, /16: per-pixel rotation and step jitter, removed by the 4×4 blur.
_BAYER = (
    np.array([[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]], np.float32) + 0.5
) / 16.0


def ssao(
    depth: np.ndarray,
    normal: np.ndarray,
    *,
    radius: float,
    focal_px: float | None = None,
    pixel_size: float | None = None,
    principal_point: tuple[float, float] | None = None,
    directions: int = 8,
    steps: int = 4,
    bias_deg: float = 6.0,
    max_radius_px: float | None = None,
    blur: bool = True,
    threads: int | None = None,
) -> np.ndarray:
    """Normal-oriented horizon-based screen-space ambient occlusion (see the module docstring).

    Parameters
    ----------
    depth : (H, W) planar depth (−z camera), > 0; +inf (or non-finite / ≤ 0) on background.
    normal : (H, W, 3) camera-space unit normals (OpenGL: +z towards the camera).
    radius : R, the occlusion radius in scene units, > 0.
    focal_px : focal length in pixels (perspective camera). Give exactly one of ``focal_px``
        and ``pixel_size``.
    pixel_size : scene-unit size of one pixel (orthographic camera).
    principal_point : (cx, cy) in pixels, measured from the top-left corner of the image;
        default the image centre (W/2, H/2).
    directions : D, number of marching directions, 1..32.
    steps : S, samples per direction, 1..32.
    bias_deg : tangent bias angle t in degrees, [0, 60).
    max_radius_px : cap of the projected radius in pixels (default 0.1 × H, at least 4), so a
        surface close to the camera does not march across the whole image.
    blur : smooth the interleaved pattern with the 4×4 masked box blur.
    threads : worker threads over chunks of pixels (default: the CPU count, at most 8).

    Returns
    -------
    (H, W) float32 in [0, 1], 1 = unoccluded; 1 on background pixels.
    """
    depth = np.asarray(depth, np.float32)
    normal = np.asarray(normal, np.float32)
    if depth.ndim != 2:
        raise ValueError(f"depth must be (H, W), got shape {depth.shape}")
    if normal.shape != (*depth.shape, 3):
        raise ValueError(f"normal must be (H, W, 3) matching depth, got shape {normal.shape}")
    if not (math.isfinite(radius) and radius > 0.0):
        raise ValueError(f"radius must be > 0 (scene units), got {radius}")
    if (focal_px is None) == (pixel_size is None):
        raise ValueError("give exactly one of focal_px (perspective) or pixel_size (orthographic)")
    if focal_px is not None and not (math.isfinite(focal_px) and focal_px > 0.0):
        raise ValueError(f"focal_px must be > 0, got {focal_px}")
    if pixel_size is not None and not (math.isfinite(pixel_size) and pixel_size > 0.0):
        raise ValueError(f"pixel_size must be > 0, got {pixel_size}")
    if not 1 <= directions <= 32:
        raise ValueError(f"directions must be in 1..32, got {directions}")
    if not 1 <= steps <= 32:
        raise ValueError(f"steps must be in 1..32, got {steps}")
    if not 0.0 <= bias_deg < 60.0:
        raise ValueError(f"bias_deg must be in [0, 60), got {bias_deg}")

    h, w = depth.shape
    cx, cy = (w / 2.0, h / 2.0) if principal_point is None else principal_point
    valid = np.isfinite(depth) & (depth > 0.0)
    z = np.where(valid, depth, _FAR).astype(np.float32)
    cap = max(4.0, 0.1 * h) if max_radius_px is None else float(max_radius_px)
    marcher = _Marcher(
        z=z,
        normal=normal,
        focal_px=focal_px,
        pixel_size=pixel_size,
        center=(float(cx), float(cy)),
        radius=float(radius),
        cap=cap,
        directions=directions,
        steps=steps,
        sin_bias=math.sin(math.radians(bias_deg)),
    )
    # only covered pixels are marched, in chunks of 16k that stay in cache
    index = np.flatnonzero(valid)
    occlusion = np.zeros(h * w, np.float32)
    chunks = [index[i : i + _CHUNK] for i in range(0, index.size, _CHUNK)]
    workers = max(1, min(threads or (os.cpu_count() or 1), 8, len(chunks)))
    if workers == 1:
        for chunk in chunks:
            occlusion[chunk] = marcher.occlusion(chunk)
    else:
        with ThreadPoolExecutor(workers) as pool:
            for chunk, occ in zip(chunks, pool.map(marcher.occlusion, chunks), strict=True):
                occlusion[chunk] = occ
    ao = 1.0 - occlusion.reshape(h, w)
    np.clip(ao, 0.0, 1.0, out=ao)
    if blur:
        fmask = valid.astype(np.float32)
        num = cv2.blur(ao * fmask, (4, 4), borderType=cv2.BORDER_REFLECT)
        den = cv2.blur(fmask, (4, 4), borderType=cv2.BORDER_REFLECT)
        ao = np.where(den > 1e-6, num / np.maximum(den, 1e-6), 1.0).astype(np.float32)
    ao[~valid] = 1.0
    return np.asarray(ao, np.float32)


_CHUNK = 16384  # cv2.remap wants maps narrower than 32767


class _Pixels(NamedTuple):
    """Pixels of :meth:`_Marcher.occlusion`, each field one row (1, N) float32."""

    gx: np.ndarray  # column
    gy: np.ndarray  # row
    z: np.ndarray  # depth
    normal: tuple[np.ndarray, np.ndarray, np.ndarray]  # camera-space x, y, z
    pattern: np.ndarray  # place in the 4×4 rotation and jitter pattern (int)
    at: tuple[np.ndarray, np.ndarray]  # camera-space x, y of the surface point
    rstep: np.ndarray  # the march's step, pixels


class _Marcher:
    """The per-image inputs of :func:`ssao` and its inner loop over a set of pixels."""

    def __init__(
        self,
        *,
        z: np.ndarray,
        normal: np.ndarray,
        focal_px: float | None,
        pixel_size: float | None,
        center: tuple[float, float],
        radius: float,
        cap: float,
        directions: int,
        steps: int,
        sin_bias: float,
    ) -> None:
        self.z = z
        self.normal = normal.reshape(-1, 3)
        self.width = z.shape[1]
        if focal_px is not None:
            self.ortho = False
            self.scale = np.float32(1.0 / focal_px)
            self.radius_px = np.float32(radius * focal_px)  # divided by depth per pixel
        else:
            assert pixel_size is not None
            self.ortho = True
            self.scale = np.float32(pixel_size)
            self.radius_px = np.float32(radius / pixel_size)
        self.offset = (
            np.float32((0.5 - center[0]) * self.scale),
            np.float32((0.5 - center[1]) * self.scale),
        )
        self.r2 = np.float32(radius * radius)
        self.inv_r2 = np.float32(1.0 / (radius * radius))
        self.cap = np.float32(cap)
        self.steps = steps
        self.sin_bias = np.float32(sin_bias)
        # per-pixel rotation (Bayer) and step jitter (transposed Bayer), 4×4 periodic
        angles = _BAYER[None] + np.arange(directions, dtype=np.float32)[:, None, None]
        angles *= np.float32(2.0 * math.pi / directions)
        self.cos_k = np.cos(angles).astype(np.float32)  # (D, 4, 4)
        self.sin_k = np.sin(angles).astype(np.float32)
        self.jitter = np.ascontiguousarray(_BAYER.T)
        self.norm = np.float32(1.0 / ((1.0 - sin_bias) * directions))

    def _pixels(self, index: np.ndarray) -> _Pixels:
        """What :meth:`occlusion` needs of the pixels ``index``, each as one row."""
        shape = (1, index.size)
        gy_i, gx_i = np.divmod(index, self.width)
        gx = gx_i.astype(np.float32).reshape(shape)
        gy = gy_i.astype(np.float32).reshape(shape)
        z = self.z.reshape(-1)[index].reshape(shape)
        nrm = self.normal[index]
        nx, ny, nz = (np.ascontiguousarray(nrm[:, i]).reshape(shape) for i in range(3))
        pattern = ((gy_i % 4) * 4 + gx_i % 4).reshape(shape)
        scale = self.scale
        ox, oy = self.offset
        if self.ortho:
            rstep = np.full(shape, min(self.radius_px, self.cap), np.float32)
            at = (gx * scale + ox, -(gy * scale + oy))
        else:
            rstep = np.minimum(self.radius_px / z, self.cap)
            at = ((gx * scale + ox) * z, -(gy * scale + oy) * z)
        rstep *= np.float32(1.0 / self.steps)
        return _Pixels(gx, gy, z, (nx, ny, nz), pattern, at, rstep)

    def occlusion(self, index: np.ndarray) -> np.ndarray:
        """Occlusion in [0, 1] (before 1 − ·) of the flat pixel indices ``index``."""
        shape = (1, index.size)  # cv2.remap wants 2-D maps: one row of pixels
        gx, gy, z, (nx, ny, nz), pattern, (px, py), rstep = self._pixels(index)
        scale = self.scale
        ox, oy = self.offset
        jitter = self.jitter.reshape(-1)[pattern]
        occ = np.zeros(shape, np.float32)
        horizon = np.empty(shape, np.float32)
        sx = np.empty(shape, np.float32)
        sy = np.empty(shape, np.float32)
        tmp = np.empty(shape, np.float32)
        t = np.empty(shape, np.float32)
        far_value = float(_FAR)
        for cos_k, sin_k in zip(self.cos_k, self.sin_k, strict=True):
            step_x = cos_k.reshape(-1)[pattern] * rstep
            step_y = sin_k.reshape(-1)[pattern] * rstep
            horizon.fill(self.sin_bias)
            for j in range(self.steps):
                np.add(jitter, np.float32(j), out=t)  # j + (0, 1): step 0 may stay on the pixel
                np.multiply(step_x, t, out=sx)
                sx += gx
                np.rint(sx, out=sx)
                np.multiply(step_y, t, out=sy)
                sy += gy
                np.rint(sy, out=sy)
                zs = cv2.remap(
                    self.z,
                    sx,
                    sy,
                    cv2.INTER_NEAREST,
                    borderMode=cv2.BORDER_CONSTANT,
                    borderValue=far_value,
                ).reshape(shape)
                # w = S − P, S the sample's camera-space position
                sx *= scale
                sx += ox
                sy *= scale
                sy += oy
                if self.ortho:
                    wx = sx - px
                    wy = -sy - py
                else:
                    wx = sx * zs - px
                    wy = sy * zs
                    wy += py
                    np.negative(wy, out=wy)
                wz = z - zs
                d2 = wx * wx
                np.multiply(wy, wy, out=tmp)
                d2 += tmp
                np.multiply(wz, wz, out=tmp)
                d2 += tmp
                wx *= nx
                wy *= ny
                wx += wy
                wz *= nz
                wx += wz  # n·w
                # falloff W = 1 − |w|²/R², 0 beyond R (and on background samples)
                np.minimum(d2, self.r2, out=tmp)
                tmp *= -self.inv_r2
                tmp += np.float32(1.0)
                np.maximum(d2, np.float32(1e-30), out=d2)
                np.sqrt(d2, out=d2)
                wx /= d2  # sin h
                wx[tmp <= 0.0] = -1.0  # beyond R: neither occludes nor raises the horizon
                np.subtract(wx, horizon, out=wy)
                np.maximum(wy, np.float32(0.0), out=wy)
                wy *= tmp
                occ += wy
                np.maximum(horizon, wx, out=horizon)
        occ *= self.norm
        return occ.reshape(-1)
