"""Masks: restrict any pipeline step to objects, materials or any layer of the frame.

Every operator takes ``mask`` (:data:`MASK_SYNTAX`), ``mask_feather``, ``mask_amount`` and
``mask_stats`` (:class:`service.operators.base.Params`). :meth:`Operator.run
<service.operators.base.Operator.run>` runs a step and blends every layer it writes with what
was there before (:func:`blend_layers`; zero for a layer it adds)::

    out = in + m · (op(in) − in)

where ``m`` (:func:`matte`) is the mask's coverage in [0, 1] (exact at anti-aliased edges for
Cryptomatte), feathered and scaled by ``mask_amount``. Pixels where m = 0 keep their input bit
for bit; where m = 1 they are the step's result bit for bit. With ``mask_stats`` the step's
statistics (automatic white levels, the congruence score) are measured where m > 0 only
(``Context.region``).
"""

from __future__ import annotations

import fnmatch
import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from gbuffer import cryptomatte
from gbuffer.errors import FrameError
from gbuffer.frame import Frame
from service.errors import PipelineError
from service.images import load_image

MASK_SYNTAX = (
    "a layer or channel of the file (`mask`, `mask.Y`, `ViewLayer.AO.R`) or a one-channel "
    "buffer (`ao`, `coverage`), or a grey image file (a painted mask, resized to the frame; "
    "not over HTTP); `cryptomatte:NAME[,NAME...]` (fnmatch wildcards such as "
    "`rock*`; the layer is chosen automatically, objects first, or named: "
    "`cryptomatte/CryptoMaterial:NAME`); `index:LAYER=V[,V...]` (an object or material index "
    "pass, e.g. `index:ViewLayer.IndexOB=3`); a leading `!` inverts the mask"
)
#: The parameters every operator takes for its mask.
MASK_FIELDS = ("mask", "mask_feather", "mask_amount", "mask_stats")

_CRYPTO = re.compile(r"cryptomatte(?:/(?P<layer>[^:]+))?:(?P<names>.+)", re.S)
_INDEX = re.compile(r"index:(?P<layer>[^=]+)=(?P<values>[-+0-9., ]+)", re.S)


@dataclass(frozen=True)
class MaskSpec:
    """A parsed ``mask``: ``kind`` (``layer``, ``cryptomatte``, ``index``), the layer it reads
    (``None``: the Cryptomatte layer chosen automatically), the names or index values it keeps
    and whether it is inverted."""

    kind: str
    layer: str | None
    names: tuple[str, ...] = ()
    values: tuple[float, ...] = ()
    invert: bool = False


def parse(text: str) -> MaskSpec:
    """A mask specification parsed (:data:`MASK_SYNTAX`), or ValueError saying what is wrong."""
    body = text.strip()
    invert = body.startswith("!")
    body = body[1:].strip() if invert else body
    if not body:
        raise ValueError(f"empty mask {text!r}; expected {MASK_SYNTAX}")
    crypto = _CRYPTO.fullmatch(body)
    if crypto:
        names = tuple(n.strip() for n in crypto["names"].split(",") if n.strip())
        if not names:
            raise ValueError(f"mask {text!r} names no Cryptomatte name")
        return MaskSpec("cryptomatte", crypto["layer"], names, invert=invert)
    if body.startswith("index:"):
        index = _INDEX.fullmatch(body)
        try:
            values = tuple(float(v) for v in index["values"].split(",")) if index else ()
        except ValueError:
            values = ()
        if index is None or not values:
            raise ValueError(f"mask {text!r}: expected index:LAYER=V[,V...], e.g. index:IndexOB=3")
        return MaskSpec("index", index["layer"].strip(), values=values, invert=invert)
    if body.startswith("cryptomatte"):
        raise ValueError(f"mask {text!r}: expected cryptomatte:NAME or cryptomatte/LAYER:NAME")
    return MaskSpec("layer", body, invert=invert)


#: Characters of a mask's text a warning shows (a mask may be 4096 long, and warnings go out
#: as HTTP headers).
_SHOWN = 120


def shown(text: str, quoted: bool = True) -> str:
    """``text`` for a warning: its ``repr`` (with ``quoted``), cut to :data:`_SHOWN`
    characters with "…" where it is longer."""
    out = repr(text) if quoted else text
    return out if len(out) <= _SHOWN else out[: _SHOWN - 1] + "…"


def layer_plane(frame: Frame, name: str, what: str) -> np.ndarray:
    """One channel by name: a one-channel buffer (``ao``), a layer of the frame (its only
    channel, or X/Y/R/A) or ``layer.X``; PipelineError naming ``what`` when there is none."""
    buffer = frame.buffers.get(name)
    if buffer is not None and buffer.ndim == 2:
        return buffer
    channels = frame.layer(name)
    if not channels:
        layer, _, channel = name.rpartition(".")
        channels = {k: v for k, v in frame.layer(layer).items() if k == channel} if layer else {}
    if len(channels) == 1:
        return next(iter(channels.values()))
    for key in ("X", "Y", "R", "A"):
        if key in channels:
            return channels[key]
    raise PipelineError(
        f"{what}: no layer {name!r} with one channel in the file"
        + (f" (it has {', '.join(sorted(channels))})" if channels else "")
    )


def plane(frame: Frame, name: str, what: str, files: bool) -> np.ndarray:
    """:func:`layer_plane`, or the grey image file ``name`` (a painted mask or gain map; values
    as stored, 8/16-bit scaled to [0, 1]) resized to the frame, where this run may read files
    and the file exists."""
    if not (files and Path(name).is_file()):
        return layer_plane(frame, name, what)
    img = load_image(name, srgb=False, grey=True)
    h, w = frame.shape
    return np.asarray(cv2.resize(img, (w, h), interpolation=cv2.INTER_LINEAR), np.float32)


def _raw(frame: Frame, spec: MaskSpec, text: str, files: bool, warnings: list[str]) -> np.ndarray:
    if spec.kind == "cryptomatte":
        try:
            layer, chosen = cryptomatte.find_layer(frame, spec.layer, list(spec.names), files)
        except FrameError as exc:
            raise PipelineError(f"mask {text!r}: {exc}") from None
        unmatched = [p for p in spec.names if not any(fnmatch.fnmatchcase(n, p) for n in chosen)]
        if unmatched:  # (a misspelt name among others that match)
            warnings.append(
                f"mask {shown(text)}: no name of {layer.name} matches "
                f"{shown(', '.join(map(repr, unmatched)), quoted=False)}; the others are used"
            )
        return cryptomatte.matte(frame, layer, list(chosen.values()))
    values = plane(frame, spec.layer or "", f"mask {text!r}", files and spec.kind == "layer")
    if spec.kind == "index":
        hit = np.zeros(values.shape, bool)
        for value in spec.values:
            hit |= np.abs(values - np.float32(value)) < 0.5
        return hit.astype(np.float32)
    return np.clip(np.nan_to_num(values, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)


def matte(
    frame: Frame,
    text: str,
    feather: float = 0.0,
    amount: float = 1.0,
    files: bool = True,
    warnings: list[str] | None = None,
) -> np.ndarray:
    """(H, W) float32 in [0, 1]: the mask ``text`` on ``frame``, inverted when it says so,
    blurred by a Gaussian of σ = ``feather`` × the image height, times ``amount``. ``files``:
    whether a Cryptomatte sidecar manifest beside the file may be read (not over HTTP).
    ``warnings``: where to say what the user may not have meant (Cryptomatte names that match
    nothing while others do)."""
    try:
        spec = parse(text)
    except ValueError as exc:
        raise PipelineError(str(exc)) from None
    m = np.ascontiguousarray(_raw(frame, spec, text, files, [] if warnings is None else warnings))
    if spec.invert:
        m = np.float32(1.0) - m
    if feather > 0.0:
        sigma = feather * frame.image_height
        m = np.asarray(cv2.GaussianBlur(m, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE))
    if amount != 1.0:
        m = m * np.float32(amount)
    return np.asarray(np.clip(m, 0.0, 1.0), np.float32)


def blend(before: np.ndarray | None, after: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``before + m · (after − before)`` (``before`` None: zero), exactly ``before`` where
    m = 0 and exactly ``after`` where m = 1."""
    w = m[..., None] if after.ndim == 3 else m
    old = np.zeros(after.shape, np.float32) if before is None else before
    mixed = old + w * (after - old)
    return np.asarray(np.where(w <= 0.0, old, np.where(w >= 1.0, after, mixed)), np.float32)


def blend_layers(pool: dict[str, np.ndarray], before: dict[str, np.ndarray], m: np.ndarray) -> None:
    """Blend every array of ``pool`` the step replaced or added; those it dropped fade out."""
    for name, after in list(pool.items()):
        old = before.get(name)
        if old is after or after.shape[:2] != m.shape:
            continue
        pool[name] = blend(old if old is not None and old.shape == after.shape else None, after, m)
    for name, old in before.items():
        if name not in pool and old.shape[:2] == m.shape:
            pool[name] = blend(old, np.zeros(old.shape, np.float32), m)
