"""The working space of a frame, and named spaces through OpenColorIO.

A frame's linear RGB space comes, in this order, from

1. the user (``--colorspace NAME`` on the command line, the ``colorspace`` form field over HTTP,
   ``ReadOptions.colorspace``): a colour space of the OpenColorIO config;
2. the EXR ``chromaticities`` attribute of the primary part (primaries and white: the matrix
   follows without OCIO, :func:`ops.colorspace.rgb_to_xyz`);
3. the ``colorInteropID`` attribute (the ASWF colour interop ID, e.g. ``lin_ap1_scene``, that
   OpenImageIO 3 writes; a name of the OCIO config);
4. the renderer preset's default (``Preset.colorspace``: Blender's scene-linear Rec.709);
5. else linear Rec.709 (D65).

The OCIO config is the file ``$OCIO`` names when set, else OCIO's built-in studio config
(:data:`BUILTIN_CONFIG`, ACES 2 views). A named space must be scene-referred and linear: its
RGB-to-XYZ matrix is the standard one for the spaces of :data:`ops.colorspace.KNOWN` and is
otherwise measured through the config's ``aces_interchange`` role (ACES2065-1, whose primaries
are known).
"""

from __future__ import annotations

import dataclasses
import functools
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from gbuffer.atomic import regular_file
from gbuffer.errors import OptionError
from ops.colorspace import (
    ACES_AP0,
    KNOWN,
    LINEAR_REC709,
    ColorSpace,
    conversion,
    from_chromaticities,
    rgb_to_xyz,
)

__all__ = [
    "BUILTIN_CONFIG",
    "RAW_VIEW",
    "View",
    "config",
    "config_name",
    "display_processor",
    "from_header",
    "named",
    "resolve",
]

#: OCIO's built-in config used when ``$OCIO`` is not set.
BUILTIN_CONFIG = "ocio://studio-config-latest"

#: Test colours of the linearity check: the three primaries and a mixture of them.
_PROBE = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, 0.25, 2.0]], np.float32)


def config_name() -> str:
    """The config in use: ``$OCIO`` when set, else :data:`BUILTIN_CONFIG`."""
    return os.environ.get("OCIO") or BUILTIN_CONFIG


def config() -> Any:
    """The OpenColorIO config of :func:`config_name` (loaded once per name)."""
    return _load(config_name())


def _ocio() -> Any:
    """The OpenColorIO module, imported where a config is used (not to read or enhance a frame
    in the standard spaces)."""
    import PyOpenColorIO

    return PyOpenColorIO


@functools.cache
def _load(name: str) -> Any:
    """The config ``name``: a built-in one (``ocio://…``), or a regular file (a FIFO is refused
    before OpenColorIO opens it and waits for a writer)."""
    ocio = _ocio()
    try:
        if not name.startswith("ocio://"):
            regular_file(name)
        return ocio.Config.CreateFromFile(name)
    except OSError as exc:
        raise OptionError(f"cannot load the OCIO config {name!r}: {exc.strerror or exc}") from None
    except Exception as exc:  # (ocio.Exception, and ExceptionMissingFile, which is not one)
        raise OptionError(f"cannot load the OCIO config {name!r}: {exc}") from None


def _linear_spaces(cfg: Any) -> list[str]:
    return [
        cs.getName()
        for cs in cfg.getColorSpaces()
        if cs.getEncoding() == "scene-linear" and not cs.isData()
    ]


def _measured(cfg: Any, name: str) -> np.ndarray:
    """RGB-to-XYZ of a linear OCIO space through ACES2065-1; OptionError when not linear."""
    target = cfg.getRoleColorSpace("aces_interchange")
    if not target:
        raise OptionError(
            f"colour space {name!r}: the OCIO config {config_name()!r} has no aces_interchange "
            "role to measure its primaries through"
        )
    proc = cfg.getProcessor(name, target).getDefaultCPUProcessor()
    probe = _PROBE.copy()
    proc.applyRGB(probe)
    m_ap0 = probe[:3].T.astype(np.float64)  # columns: the primaries in AP0
    if not np.allclose(probe[3], m_ap0 @ _PROBE[3], rtol=1e-3, atol=1e-5):
        raise OptionError(
            f"colour space {name!r} is not linear; a working space must be scene-linear "
            f"(e.g. {', '.join(_linear_spaces(cfg)[:6])})"
        )
    return np.asarray(rgb_to_xyz(ACES_AP0) @ m_ap0)


def named(name: str, source: str = "--colorspace") -> ColorSpace:
    """The linear space ``name`` (a name, alias or role) of the OCIO config, or OptionError."""
    if name in KNOWN:  # the standard spaces need no config
        return from_chromaticities(name, KNOWN[name], source)
    cfg = config()
    cs = cfg.getColorSpace(name)
    if cs is None:
        raise OptionError(
            f"colour space {name!r} is not in the OCIO config {config_name()!r}; its linear "
            f"spaces: {', '.join(_linear_spaces(cfg))}"
        )
    canonical = str(cs.getName())
    if cs.isData() or cs.getReferenceSpaceType() != _ocio().REFERENCE_SPACE_SCENE:
        raise OptionError(f"colour space {name!r} is not a scene-referred colour space")
    if canonical in KNOWN:
        return from_chromaticities(canonical, KNOWN[canonical], source)
    return ColorSpace(canonical, _measured(cfg, canonical), source)


def _chroma_name(chroma: tuple[float, ...]) -> str:
    """The name of a known space within 1e-4 of ``chroma``, else the numbers."""
    for name, known in KNOWN.items():
        if max(abs(a - b) for a, b in zip(chroma, known, strict=True)) < 1e-4:
            return name
    return "chromaticities " + " ".join(f"{v:.4g}" for v in chroma)


#: Header attribute naming the working space (the ASWF colour interop ID).
INTEROP_ATTRIBUTE = "colorInteropID"


def from_header(header: Mapping[str, Any]) -> ColorSpace | None:
    """The space of an EXR header's ``chromaticities`` attribute, else of its
    ``colorInteropID``, or None without either."""
    value = header.get("chromaticities")
    interop = header.get(INTEROP_ATTRIBUTE)
    if value is None and isinstance(interop, str) and interop:
        return named(interop, f"{INTEROP_ATTRIBUTE} attribute")
    if value is None:
        return None
    try:
        chroma = tuple(float(v) for v in np.asarray(value, np.float64).ravel())
        return from_chromaticities(_chroma_name(chroma), chroma, "chromaticities attribute")
    except (TypeError, ValueError) as exc:
        raise OptionError(f"the file's chromaticities attribute is unusable: {exc}") from None


def resolve(
    explicit: str | None, header: Mapping[str, Any] | None, preset: str, default: str | None
) -> ColorSpace:
    """The working space: ``explicit`` (a name of the OCIO config), else the header's
    chromaticities or colour interop ID, else the preset's ``default`` name, else linear
    Rec.709."""
    if explicit:
        return named(explicit, "--colorspace")
    found = from_header(header) if header is not None else None
    if found is not None:
        return found
    if default:
        return named(default, f"preset default ({preset})")
    return LINEAR_REC709


def resolve_leniently(
    explicit: str | None,
    header: Mapping[str, Any],
    preset: str,
    default: str | None,
    warnings: list[str],
) -> ColorSpace:
    """:func:`resolve`, for a file being described (``depict inspect``): where no space is
    ``explicit``, a header whose colour attribute cannot be used (``chromaticities`` of no
    gamut, an unknown or non-linear ``colorInteropID``) is said in ``warnings``, and the
    preset's space used, rather than refused (an explicit name that is none is refused)."""
    try:
        return resolve(explicit, header, preset, default)
    except OptionError as exc:
        if explicit:
            raise
        fallback = resolve(None, None, preset, default)
        warnings.append(f"{exc}; described as {fallback.name}, the preset's working space")
        return fallback


#: ``--view raw``: Depict's own exposure and hard clip (sRGB curve), no view transform.
RAW_VIEW = "raw"


@dataclasses.dataclass(frozen=True)
class View:
    """A display and a view of the OCIO config to look at scene-linear pictures through;
    ``None``: the config's default display, and that display's default view. ``view="raw"``
    (:data:`RAW_VIEW`) is Depict's exposure and hard clip instead (not the config's ``Raw``)."""

    display: str | None = None
    view: str | None = None

    @property
    def raw(self) -> bool:
        return self.view == RAW_VIEW

    def resolved(self) -> tuple[str, str]:
        """(display, view) with the config's defaults filled in, or OptionError."""
        cfg = config()
        displays = list(cfg.getDisplays())
        display = self.display or cfg.getDefaultDisplay()
        if display not in displays:
            raise OptionError(
                f"display {display!r} is not in the OCIO config {config_name()!r}; displays: "
                f"{', '.join(displays)}"
            )
        views = list(cfg.getViews(display))
        view = self.view or cfg.getDefaultView(display)
        if view not in views:
            raise OptionError(
                f"view {view!r} is not a view of display {display!r}; views: "
                f"{', '.join(views)}, or {RAW_VIEW} (exposure and clip)"
            )
        return display, view


def display_processor(space: ColorSpace, view: View) -> tuple[Any, np.ndarray | None]:
    """The OCIO CPU processor from ``space`` to ``view``'s display, and the 3×3 matrix to apply
    first (None when the config knows ``space`` by name; else to its ACES2065-1)."""
    display, name = view.resolved()
    return _processor(config_name(), space.name, space.matrix.tobytes(), display, name)


@functools.cache
def _processor(
    config_key: str, name: str, matrix: bytes, display: str, view: str
) -> tuple[Any, np.ndarray | None]:
    cfg = _load(config_key)
    cs = cfg.getColorSpace(name)
    m = np.frombuffer(matrix, np.float64).reshape(3, 3)
    pre: np.ndarray | None = None
    if cs is None or not np.allclose(named(str(cs.getName()), "").matrix, m, atol=1e-6):
        target = cfg.getRoleColorSpace("aces_interchange")
        if not target:
            raise OptionError(
                f"the OCIO config {config_key!r} has no aces_interchange role to show "
                f"{name!r} through"
            )
        src = ColorSpace(name, m)
        pre = conversion(src, from_chromaticities("ACES2065-1", ACES_AP0, "")).astype(np.float32)
        name = str(target)
    transform = _ocio().DisplayViewTransform(src=name, display=display, view=view)
    return cfg.getProcessor(transform).getDefaultCPUProcessor(), pre
