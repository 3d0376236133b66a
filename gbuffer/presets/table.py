"""The renderer presets, as data: one :class:`~gbuffer.presets.spec.Preset` per renderer.

To support another renderer, add a :class:`Preset` here and put it in :data:`PRESETS`: its
layer names, conventions and :class:`Detection` clues are all that reading and detecting its
files need; the ``--preset`` help, the HTTP field description and the README's table
(``make docs``) follow from it.
"""

from __future__ import annotations

from gbuffer.errors import FrameError
from gbuffer.frame import LOBES
from gbuffer.presets.spec import (
    ChannelSet,
    Detection,
    HeaderMark,
    LayerNames,
    LobeSpec,
    NamePrefix,
    PartName,
    PassNames,
    Preset,
)

#: Blender's pass names (3.x-4.x and Blender 5's aliases) behind the view-layer prefix.
BLENDER_PASSES = PassNames(
    passes=(
        "Combined",
        "Depth",
        "Normal",
        "Position",
        "DiffDir",
        "DiffInd",
        "DiffCol",
        "GlossDir",
        "GlossCol",
        "TransDir",
        "TransCol",
        "Emit",
        "Env",
        "AO",
        "Diffuse Direct",
        "Diffuse Color",
        "Glossy Direct",
        "Glossy Color",
        "Ambient Occlusion",
        "Emission",
        "Environment",
    ),
    reason="Blender pass names (<ViewLayer>.<pass>.<channel>)",
)

BLENDER = Preset(
    name="blender",
    description="Blender Cycles/EEVEE multilayer EXR (3.x-4.x pass names, Blender 5 aliases)",
    buffers={
        "beauty": ("Combined", "Image"),
        "alpha": ("Combined.A", "Alpha"),
        "depth": ("Depth", "Z"),
        "albedo": ("Denoising Albedo", "DiffCol", "Diffuse Color"),
        "ao": ("AO", "Ambient Occlusion"),
    },
    normal=(("Normal", "world"),),
    position=(("Position", "world"),),
    lobes={
        "diffuse": LobeSpec(
            light=(("DiffDir", "DiffInd"), ("Diffuse Direct", "Diffuse Indirect")),
            color=("DiffCol", "Diffuse Color"),
        ),
        "specular": LobeSpec(
            light=(("GlossDir", "GlossInd"), ("Glossy Direct", "Glossy Indirect")),
            color=("GlossCol", "Glossy Color"),
        ),
        "transmission": LobeSpec(
            light=(("TransDir", "TransInd"), ("Transmission Direct", "Transmission Indirect")),
            color=("TransCol", "Transmission Color"),
        ),
    },
    depth_kind="planar",
    depth_background=1e9,
    view_layer=BLENDER_PASSES,
    colorspace="Linear Rec.709 (sRGB)",  # Blender's scene-linear default (filmic/AgX config)
    detection=Detection(
        header_keys="BlenderMultiChannel",
        software=("blender",),
        channels=(BLENDER_PASSES,),
        rank=0,
    ),
)

ARNOLD = Preset(
    name="arnold",
    description="Arnold AOVs (N/P world space, Z = distance to the camera, AI_BIG background)",
    buffers={
        "beauty": ("", "RGBA", "beauty"),
        "alpha": ("A", "RGBA.A"),
        "depth": ("Z", "depth"),
        "albedo": ("diffuse_albedo", "albedo"),
        "ao": ("ao", "AO", "occlusion"),
    },
    normal=(("N", "world"),),
    position=(("P", "world"),),
    lobes={
        "diffuse": LobeSpec(
            radiance=(("diffuse_direct", "diffuse_indirect"), ("diffuse",)),
            color=("diffuse_albedo",),
        ),
        "specular": LobeSpec(
            radiance=(("specular_direct", "specular_indirect"), ("specular",)),
            color=("specular_albedo",),
        ),
        "transmission": LobeSpec(
            radiance=(("transmission_direct", "transmission_indirect"), ("transmission",)),
            color=("transmission_albedo",),
        ),
    },
    depth_kind="distance",
    depth_background=1e10,
    detection=Detection(
        header_keys="(?i:arnold/).*",
        software=("arnold",),
        channels=(
            LayerNames(
                frozenset(
                    {
                        "diffuse_direct",
                        "diffuse_indirect",
                        "diffuse_albedo",
                        "specular_direct",
                        "specular_albedo",
                        "transmission_direct",
                        "coat_direct",
                        "sss_direct",
                    }
                ),
                label="Arnold AOV names",
                unless=frozenset({"N.X", "depth.Z"}),  # Depict's canonical names
            ),
        ),
        rank=3,  # generic names (Karma writes some too): after the other renderers'
    ),
)

VRAY = Preset(
    name="vray",
    description="V-Ray render elements (VRayNormals camera space, raw Z, cameraTransform)",
    buffers={
        "beauty": ("", "RGBA", "rgba"),
        "alpha": ("A", "VRayAlpha", "alpha"),
        "depth": ("Z",),
        "albedo": ("VRayDiffuseFilter", "diffuse"),
    },
    normal=(("VRayNormals", "camera"), ("normals", "camera"), ("Normals", "camera")),
    lobes={
        "diffuse": LobeSpec(
            radiance=(("VRayLighting", "VRayGlobalIllumination"), ("lighting", "gi")),
            light=(("VRayRawLighting", "VRayRawGlobalIllumination"), ("lighting_raw", "gi_raw")),
            color=("VRayDiffuseFilter", "diffuse"),
        ),
        "specular": LobeSpec(
            radiance=(("VRayReflection", "VRaySpecular"), ("reflection", "specular")),
            light=(("VRayRawReflection",), ("reflection_raw",)),
            color=("VRayReflectionFilter", "reflection_filter"),
        ),
        "transmission": LobeSpec(
            radiance=(("VRayRefraction",), ("refraction",)),
            light=(("VRayRawRefraction",), ("refraction_raw",)),
            color=("VRayRefractionFilter", "refraction_filter"),
        ),
    },
    depth_kind="planar",
    depth_background=1e10,
    detection=Detection(
        header_keys="vrayInfo/.*|cameraTransform",
        software=("v-ray", "vray"),
        channels=(NamePrefix(("VRay", "vray"), "V-Ray render element names (VRay*)"),),
        rank=1,
    ),
)

RENDERMAN = Preset(
    name="renderman",
    description="RenderMan RIS AOVs (Nn/P camera space left-handed, z planar, __Nworld/__Pworld)",
    buffers={
        "beauty": ("", "Ci", "beauty"),
        "alpha": ("A", "a", "Ci.a", "Ci.A"),
        "depth": ("z", "Z"),
        "albedo": ("albedo", "diffuseColor"),
        "ao": ("occlusion", "ao"),
    },
    normal=(("Nn", "camera-lh"), ("__Nworld", "world"), ("N", "camera-lh")),
    position=(("__Pworld", "world"), ("P", "camera-lh")),
    lobes={
        "diffuse": LobeSpec(
            radiance=(
                ("directDiffuse", "indirectDiffuse"),
                ("directDiffuseLobe", "indirectDiffuseLobe"),
            ),
            color=("albedo", "diffuseColor"),
        ),
        "specular": LobeSpec(
            radiance=(
                ("directSpecular", "indirectSpecular"),
                (
                    "directSpecularPrimaryLobe",
                    "indirectSpecularPrimaryLobe",
                    "directSpecularRoughLobe",
                    "indirectSpecularRoughLobe",
                ),
            ),
        ),
        "transmission": LobeSpec(
            radiance=(("transmissive",), ("transmissiveGlassLobe",)),
        ),
    },
    depth_kind="planar",
    depth_background=1e10,
    detection=Detection(
        header_keys="(?i:renderman|prman|pixar).*",
        software=("renderman", "prman"),
        channels=(
            LayerNames(
                frozenset({"Nn", "__Nworld", "__Pworld", "Ci", "directDiffuse", "directSpecular"}),
                label="RenderMan AOV names",
            ),
        ),
        rank=2,
    ),
)

KARMA = Preset(
    name="karma",
    description="Houdini Karma render vars (multi-part by layer name, N/P world space)",
    buffers={
        "beauty": ("C", "beauty", ""),
        "alpha": ("C.A", "A"),
        "depth": ("depth", "Pz", "Z", "z"),
        "albedo": ("albedo", "diffuse_albedo", "basecolor"),
        "ao": ("occlusion", "ao", "AO"),
    },
    normal=(("N", "world"),),
    position=(("P", "world"),),
    lobes={
        "diffuse": LobeSpec(
            radiance=(
                ("directdiffuse", "indirectdiffuse"),
                ("combineddiffuse",),
                ("diffuse_direct", "diffuse_indirect"),
                ("diffuse",),
            ),
            color=("albedo", "diffuse_albedo"),
        ),
        "specular": LobeSpec(
            radiance=(
                ("glossyreflection", "indirectglossyreflection"),
                ("combinedglossyreflection",),
                ("specular_direct", "specular_indirect"),
                ("specular",),
            ),
            color=("specular_albedo",),
        ),
        "transmission": LobeSpec(
            radiance=(("glossytransmission",), ("transmission",)),
            color=("transmission_albedo",),
        ),
    },
    depth_kind="planar",
    depth_background=1e10,
    detection=Detection(
        header_keys="(?i:karma|houdini).*",
        software=("karma", "houdini"),
        channels=(PartName("C", "multi-part file with a part named 'C' (Karma beauty)"),),
        rank=4,
    ),
)

CANONICAL = Preset(
    name="canonical",
    description="Depict's own names (the table above): R G B A, N.XYZ, depth.Z, P.XYZ, lobes, AO.X",
    buffers={
        "beauty": ("",),
        "alpha": ("A",),
        "depth": ("depth",),
        "albedo": ("albedo",),
        "ao": ("AO",),
        "roughness": ("roughness",),
        "coverage": ("coverage",),
    },
    normal=(("N", "camera"),),
    position=(("P", "camera"),),
    lobes={
        lobe: LobeSpec(radiance=((lobe,),), light=((f"{lobe}.light",),), color=(f"{lobe}.color",))
        for lobe in LOBES
    },
    depth_kind="planar",
    depth_background=1e30,
    detection=Detection(
        software=("depict",),
        channels=(
            HeaderMark("depict/"),  # after the renderers': Depict marks the files it writes back
            ChannelSet(
                (frozenset({"N.X", "N.Y", "N.Z"}), frozenset({"depth.Z"})),
                "Depict canonical channel names (N.X/Y/Z, depth.Z)",
            ),
        ),
        rank=5,
    ),
)

#: Presets by name.
PRESETS: dict[str, Preset] = {
    p.name: p for p in (BLENDER, ARNOLD, VRAY, RENDERMAN, KARMA, CANONICAL)
}
#: The preset of a file without any clue.
FALLBACK = CANONICAL


def find_preset(name: str) -> Preset:
    """The preset called ``name``, or a :class:`FrameError` listing the valid names."""
    try:
        return PRESETS[name]
    except KeyError:
        valid = ", ".join(preset_names())
        raise FrameError(f"preset={name!r} is not known; valid: {valid}") from None


def preset_names() -> tuple[str, ...]:
    """What ``--preset`` accepts: ``auto`` and every preset's name."""
    return ("auto", *PRESETS)


def preset_help() -> str:
    """The help of ``--preset`` and of the HTTP ``preset`` field."""
    return (
        "renderer preset: auto (detected from the header and channel names; `depict inspect` "
        f"says which and why) or one of {', '.join(PRESETS)}"
    )
