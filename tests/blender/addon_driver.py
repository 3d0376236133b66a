"""Drive the Depict add-on in a headless Blender, as a user would, and report what happened.

    blender -b --factory-startup --python tests/blender/addon_driver.py -- ADDON.py OUTDIR \\
        [PIPELINE_JSON]

Installs ADDON.py with Blender's own "Install Add-on" operator (into BLENDER_USER_SCRIPTS when
set) and enables it, builds a small Cycles scene (tests/blender/camera_frame.py) with the lobe
passes, runs ``bpy.ops.depict.enhance`` with the compositor option (twice: the second time on a
fresh render made with the compositor on), then renders the compositor
twice (its output linked to the result's Depict pass, then to its Combined pass) to
OUTDIR/compositor_depict.png and OUTDIR/compositor_combined.png. OUTDIR/report.json says what
the add-on registered and produced; a failure is reported there too.
"""

import json
import os
import sys
import traceback

import addon_utils
import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import camera_frame  # noqa: E402  (Blender's Python: the test scene, beside this file)

LOBE_PASSES = (
    "use_pass_diffuse_direct",
    "use_pass_diffuse_indirect",
    "use_pass_diffuse_color",
    "use_pass_glossy_direct",
    "use_pass_glossy_indirect",
    "use_pass_glossy_color",
)


def scene_setup(second_layer: bool = False) -> None:
    """The scene; with ``second_layer``, a view layer "Another" beside the active one, with
    more passes (AO too): Depict would read it, were it not told the active one."""
    camera_frame.build("PERSP", "AUTO", 35.0)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 8
    scene.cycles.use_denoising = False  # Debian's Blender has no OpenImageDenoise
    scene.render.resolution_x, scene.render.resolution_y = 160, 90
    scene.render.resolution_percentage = 100
    for name in LOBE_PASSES:
        setattr(bpy.context.view_layer, name, True)
    if second_layer:
        other = scene.view_layers.new("Another")
        extra = ("ambient_occlusion", "normal", "z", "position", "mist", "emit", "uv")
        more = (*extra, "environment", "object_index", "material_index", "shadow")
        for name in (*LOBE_PASSES, *(f"use_pass_{p}" for p in more)):
            if hasattr(other, name):
                setattr(other, name, True)


def render_compositor(path: str, socket_name: str) -> None:
    scene = bpy.context.scene
    tree = scene.node_tree
    node = tree.nodes["Depict Result"]
    composite = next(n for n in tree.nodes if n.bl_idname == "CompositorNodeComposite")
    tree.links.new(node.outputs[socket_name], composite.inputs[0])
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_depth = "8"
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)


def settings_listing() -> list:
    """The panel's settings: name, type, default (what Properties > Render > Depict shows)."""
    rna = bpy.types.Scene.bl_rna.properties["depict"].fixed_type
    out = []
    for prop in rna.properties:
        if prop.identifier == "rna_type":
            continue
        default = getattr(prop, "default", None)
        items = [i.identifier for i in getattr(prop, "enum_items", [])]
        out.append({"name": prop.name, "id": prop.identifier, "default": default, "items": items})
    return out


def main() -> None:
    argv = sys.argv[sys.argv.index("--") + 1 :]
    addon, outdir = argv[0], argv[1]
    pipeline = argv[2] if len(argv) > 2 else ""
    second_layer = len(argv) > 3 and argv[3] == "two-layers"
    report: dict = {}
    try:
        bpy.ops.preferences.addon_install(filepath=addon, overwrite=True)
        module = os.path.splitext(os.path.basename(addon))[0]
        addon_utils.enable(module, default_set=True)
        report["enabled"] = module in bpy.context.preferences.addons
        report["operator"] = hasattr(bpy.ops.depict, "enhance")
        report["panels"] = [
            c for c in ("DEPICT_PT_render", "DEPICT_PT_image") if hasattr(bpy.types, c)
        ]
        report["settings"] = settings_listing()
        scene_setup(second_layer)
        result = bpy.ops.depict.enhance(pipeline=pipeline, compositor=True)
        report["result"] = sorted(result)
        image = bpy.data.images.get("Depict Result")
        report["image"] = (
            None
            if image is None
            else {
                "name": image.name,
                "filepath": bpy.path.abspath(image.filepath),
                "type": image.type,
            }
        )
        node = bpy.context.scene.node_tree.nodes.get("Depict Result")
        report["node_outputs"] = [s.name for s in node.outputs if s.enabled] if node else []
        links = bpy.context.scene.node_tree.links
        report["composite_from"] = [
            link.from_socket.name
            for link in links
            if link.to_node.bl_idname == "CompositorNodeComposite"
        ]
        # again, rendering with the compositor now on: the saved render gains a Composite layer
        again = bpy.ops.depict.enhance(pipeline=pipeline, render=True, compositor=True)
        report["again"] = sorted(again)
        render_compositor(os.path.join(outdir, "compositor_depict.png"), "Depict")
        render_compositor(os.path.join(outdir, "compositor_combined.png"), "Combined")
    except Exception:  # everything lands in the report for the test to show
        report["error"] = traceback.format_exc()
    with open(os.path.join(outdir, "report.json"), "w") as fh:
        json.dump(report, fh, indent=2)


main()
