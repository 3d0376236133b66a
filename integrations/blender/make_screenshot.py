"""The README's screenshot of the add-on: Blender's own window, on a virtual display.

    xvfb-run -a -s "-screen 0 1600x900x24" blender --factory-startup \\
        --python integrations/blender/make_screenshot.py -- OUT.png

with ``depict`` on PATH. Blender builds the test scene of tests/blender/camera_frame.py, installs
and enables the add-on, runs Depict on the render (``bpy.ops.depict.enhance``), shows the image
"Depict Result" in the compositor (its pass "Depict" linked to the Composite and Viewer
nodes), the Viewer's image in an Image Editor with the add-on's sidebar panel, and saves the
window with Blender's screenshot operator.
"""

import os
import sys
import tempfile

import addon_utils
import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
import camera_frame  # noqa: E402  (the test scene)

OUT = sys.argv[sys.argv.index("--") + 1] if "--" in sys.argv else "blender_addon.png"


def prepare() -> None:
    os.environ.setdefault("BLENDER_USER_SCRIPTS", tempfile.mkdtemp(prefix="depict-addon-"))
    bpy.ops.preferences.addon_install(filepath=os.path.join(HERE, "depict_blender.py"))
    addon_utils.enable("depict_blender", default_set=True)
    camera_frame.build("PERSP", "AUTO", 35.0)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 32
    scene.cycles.use_denoising = False
    scene.render.resolution_x, scene.render.resolution_y = 960, 540
    for name in ("diffuse_direct", "diffuse_indirect", "diffuse_color", "glossy_direct"):
        setattr(bpy.context.view_layer, f"use_pass_{name}", True)
    for name in ("glossy_indirect", "glossy_color"):
        setattr(bpy.context.view_layer, f"use_pass_{name}", True)
    scene.depict.gamma = 2.0
    scene.depict.compositor = True
    scene.use_nodes = True  # the compositor on, as artists have it: a Composite layer is saved too
    tree = scene.node_tree
    tree.nodes.new("CompositorNodeViewer")
    bpy.ops.depict.enhance()  # the panel's settings; links the Depict pass to Composite, Viewer
    places = {
        "CompositorNodeRLayers": (400, 330),
        "CompositorNodeComposite": (720, 330),
        "CompositorNodeImage": (400, 210),
        "CompositorNodeViewer": (720, 210),
    }
    for node in tree.nodes:
        node.location = places.get(node.bl_idname, node.location)
        node.hide = node.bl_idname == "CompositorNodeRLayers"  # collapsed: not the subject
        if hasattr(node, "show_preview"):
            node.show_preview = False


def layout() -> None:
    """Blender's Compositing workspace: the node tree over the Viewer's backdrop (the Depict
    pass), the Render properties scrolled down to the add-on's panel, the Info log below."""
    window = bpy.context.window_manager.windows[0]
    window.workspace = bpy.data.workspaces["Compositing"]


def arrange() -> None:
    window = bpy.context.window_manager.windows[0]
    for area in window.screen.areas:
        if area.type == "NODE_EDITOR":
            space = area.spaces.active
            space.show_backdrop = True
            space.backdrop_zoom = 0.72
            space.backdrop_offset = (-area.width * 0.2, 0.0)  # the nodes to its right
        elif area.type == "DOPESHEET_EDITOR":  # the add-on's report instead
            area.type = "INFO"
        elif area.type == "PROPERTIES":
            area.spaces.active.context = "RENDER"
            region = next(r for r in area.regions if r.type == "WINDOW")
            with bpy.context.temp_override(window=window, area=area, region=region):
                for _ in range(12):
                    bpy.ops.view2d.scroll_down(page=True)


def shoot() -> None:
    window = bpy.context.window_manager.windows[0]
    area = max(window.screen.areas, key=lambda a: a.width * a.height)
    with bpy.context.temp_override(window=window, area=area):
        bpy.ops.screen.screenshot(filepath=os.path.abspath(OUT))
    print(f"wrote {OUT}")
    bpy.ops.wm.quit_blender()


def step(state: list) -> float | None:
    """Timer steps: let the window draw between the layout change and the screenshot."""
    if not state:
        prepare()
        state.append("prepared")
        return 5.0
    if len(state) == 1:
        layout()
        state.append("laid out")
        return 2.0
    if len(state) == 2:
        arrange()
        state.append("arranged")
        return 2.0
    shoot()
    return None


def main() -> None:
    bpy.context.preferences.view.show_splash = False
    state: list = []
    bpy.app.timers.register(lambda: step(state), first_interval=1.0)


main()
