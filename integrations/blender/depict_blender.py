"""Depict for Blender: enhance the depiction of shape in a render, from inside Blender.

Install: Edit > Preferences > Add-ons > Install..., pick this file, tick "Render: Depict".
Then Properties > Render > Depict (or the Image Editor's sidebar, tab Depict): choose an
operator and its main parameters, press Enhance. The add-on

1. takes the last render, or renders the scene when there is none or when the view layer lacked
   a pass Depict needs (Z, Normal, Position are switched on for it; the Cryptomatte passes too
   when a step's ``mask`` names Cryptomatte, e.g. the panel's Mask ``cryptomatte:Suzanne``);
2. saves it as a multilayer EXR with every pass, and the scene camera as Depict's camera JSON
   (``world_to_camera`` and the field of view of the whole frame, from Blender's own projection
   matrix, so the sensor fit is Blender's);
3. runs ``depict enhance`` (the executable set in the add-on's preferences, else ``depict`` on
   PATH), or sends the frame to a Depict server (the preferences' server, else the
   ``DEPICT_SERVER`` environment variable; ``DEPICT_API_KEY`` for its key);
4. loads the result as the image "Depict Result" (its pass "Depict" of the view layer holds the
   enhanced image) and, when asked, feeds that pass to the compositor's output.

The operator ``depict.enhance`` takes ``pipeline``: Depict's pipeline JSON (``{"steps": [...]}``
or a list of steps); empty, it is built from the panel's settings.
"""

import json
import math
import mimetypes
import os
import shutil
import subprocess
import tempfile
import urllib.error
import urllib.request
import uuid

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, PointerProperty, StringProperty

bl_info = {
    "name": "Depict",
    "author": "Depict",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Properties > Render > Depict; Image Editor > Sidebar > Depict",
    "description": "Enhance the depiction of shape in renders (Radiance Scaling, Light "
    "Alignment, 3D unsharp masking, Apparent Relief)",
    "category": "Render",
}

RESULT_IMAGE = "Depict Result"
RESULT_NODE = "Depict Result"
PASSES = ("use_pass_z", "use_pass_normal", "use_pass_position")
#: Switched on too when the pipeline names a Cryptomatte mask.
CRYPTOMATTE_PASSES = (
    "use_pass_cryptomatte_object",
    "use_pass_cryptomatte_material",
    "use_pass_cryptomatte_asset",
)
OPERATORS = (
    ("radiance_scaling", "Radiance Scaling", "scale reflected light by curvature (Vergne 2011)"),
    ("light_alignment", "Light Alignment", "align the lights with the shape, per scale (2021)"),
    ("unsharp_masking", "3D Unsharp Masking", "Cornsweet contrast along surfaces (2008)"),
    ("apparent_relief", "Apparent Relief", "cel, counter and X-Toon shading by relief (2008)"),
    ("exaggerated_shading", "Exaggerated Shading", "multi-scale grazing lights (2006)"),
    ("light_warping", "Light Warping", "lights warped by view-centred curvature (2009)"),
    ("depth_unsharp_masking", "Depth Unsharp Masking", "darken behind silhouettes (2006)"),
    ("custom", "Custom pipeline", "the pipeline JSON below"),
)


class DepictError(Exception):
    """Something the user can fix; the message says what."""


# -- settings -------------------------------------------------------------------------------------


class DepictPreferences(bpy.types.AddonPreferences):
    bl_idname = __name__

    executable: StringProperty(
        name="depict executable",
        description="the depict command (empty: 'depict' found on PATH)",
        subtype="FILE_PATH",
        default="",
    )
    server: StringProperty(
        name="Depict server",
        description="URL of a Depict server to use instead of the local command "
        "(empty: the DEPICT_SERVER environment variable, if set)",
        default="",
    )

    def draw(self, context):
        self.layout.prop(self, "executable")
        self.layout.prop(self, "server")


class DepictSettings(bpy.types.PropertyGroup):
    operator: EnumProperty(name="Operator", items=OPERATORS, default="radiance_scaling")
    gamma: FloatProperty(
        name="Gamma", description="Radiance Scaling magnitude γ", default=3.0, min=0.0, max=20.0
    )
    scenario: EnumProperty(
        name="Scenario",
        items=(
            ("auto", "Auto", "the render's lobes when it has them"),
            ("lobes", "Lobes", "scale Cycles' diffuse, glossy and transmission passes"),
            ("beauty", "Beauty", "the combined image as one lobe"),
            ("phong", "Phong", "shade the G-buffer with Depict's lights"),
        ),
        default="auto",
    )
    lla_gamma: FloatProperty(
        name="Alignment γ", description="Light Alignment γ of W_γ", default=3.0, min=0.0, max=20.0
    )
    form: EnumProperty(
        name="Form",
        items=(
            ("auto", "Auto", "ratio when the render has lobes"),
            ("ratio", "Ratio", "keep the render, add the alignment"),
            ("relight", "Relight", "shade the G-buffer with the aligned lights"),
        ),
        default="auto",
    )
    amount: FloatProperty(
        name="Amount", description="unsharp masking λ", default=1.0, min=0.0, max=10.0
    )
    style: EnumProperty(
        name="Style",
        items=(
            ("cel", "Cel", ""),
            ("counter", "Counter", ""),
            ("xtoon", "X-Toon", ""),
            ("descriptor", "Descriptor", ""),
        ),
        default="cel",
    )
    pipeline: StringProperty(
        name="Pipeline",
        description='Depict pipeline JSON, e.g. {"steps": [{"op": "radiance_scaling"}]}',
        default='{"steps": [{"op": "radiance_scaling", "params": {"gamma": 2}}]}',
    )
    mask: StringProperty(
        name="Mask",
        description="restrict the step to a matte: cryptomatte:NAME (objects, materials; "
        "wildcards, commas), index:ViewLayer.IndexOB=3, or a layer; ! inverts; empty: the "
        "whole frame",
        default="",
    )
    render: BoolProperty(
        name="Render first", description="render the scene even if there is a last render"
    )
    compositor: BoolProperty(
        name="Use in compositor",
        description="feed the Depict pass of the result to the compositor's output",
    )

    def pipeline_json(self):
        """The pipeline of the panel's settings, as JSON text."""
        params = {
            "radiance_scaling": {"gamma": self.gamma, "scenario": self.scenario},
            "light_alignment": {"gamma": self.lla_gamma, "form": self.form},
            "unsharp_masking": {"amount": self.amount},
            "apparent_relief": {"style": self.style},
        }
        if self.operator == "custom":
            return self.pipeline
        step = {"op": self.operator, "params": params.get(self.operator, {})}
        if self.mask.strip():
            step["params"]["mask"] = self.mask.strip()
        return json.dumps({"steps": [step]})


# -- the work -------------------------------------------------------------------------------------


def camera_json(scene):
    """The scene camera in Depict's camera JSON form (OpenGL convention, as Blender's)."""
    cam = scene.camera
    if cam is None:
        raise DepictError("the scene has no camera")
    render = scene.render
    scale = render.resolution_percentage / 100.0
    width, height = int(render.resolution_x * scale), int(render.resolution_y * scale)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    proj = cam.calc_matrix_camera(
        depsgraph, x=width, y=height, scale_x=render.pixel_aspect_x, scale_y=render.pixel_aspect_y
    )
    out = {"world_to_camera": [list(row) for row in cam.matrix_world.inverted()]}
    if cam.data.type == "ORTHO":
        out.update(projection="orthographic", ortho_height=2.0 / proj[1][1])
    elif cam.data.type == "PERSP":
        fov = math.degrees(2.0 * math.atan(1.0 / proj[1][1]))
        out.update(projection="perspective", fov_y_deg=fov)
    else:
        raise DepictError(f"the {cam.data.type} camera is not one Depict can use")
    return out


def ensure_render(context, force, cryptomatte=False):
    """Switch on the passes Depict needs (and Cryptomatte's when a mask names it); render when
    asked, when they were off, or when there is no last render. Returns the Render Result
    image."""
    layer = context.view_layer
    needed = PASSES + (CRYPTOMATTE_PASSES if cryptomatte else ())
    missing = [name for name in needed if not getattr(layer, name)]
    for name in missing:
        setattr(layer, name, True)
    image = bpy.data.images.get("Render Result")
    if force or missing or image is None:
        bpy.ops.render.render()
        image = bpy.data.images.get("Render Result")
    if image is None:
        raise DepictError("no render result: render the scene first (F12)")
    return image


def save_render(image, scene, path):
    """The render result with all its passes, as a 32-bit multilayer EXR."""
    settings = scene.render.image_settings
    kept = (settings.file_format, settings.color_depth, settings.exr_codec)
    try:
        settings.file_format = "OPEN_EXR_MULTILAYER"
        settings.color_depth = "32"
        settings.exr_codec = "ZIP"
        image.save_render(path, scene=scene)
    finally:
        settings.file_format, settings.color_depth, settings.exr_codec = kept
    if not os.path.isfile(path):
        raise DepictError("the render could not be saved: render the scene first (F12)")


def find_executable(prefs):
    path = bpy.path.abspath(prefs.executable) if prefs and prefs.executable else ""
    if path:
        if not os.access(path, os.X_OK):
            raise DepictError(f"the depict executable in the preferences is not one: {path}")
        return path
    found = shutil.which("depict")
    if found is None:
        raise DepictError(
            "depict is not on PATH: install Depict, set its path in the add-on's preferences, "
            "or give a Depict server (preferences or DEPICT_SERVER)"
        )
    return found


def run_local(executable, src, out, camera, pipeline, view_layer):
    cmd = [executable, "enhance", src, "-o", out, "--camera", camera, "--pipeline", pipeline]
    cmd += ["--view-layer", view_layer]
    env = {k: v for k, v in os.environ.items() if k != "DEPICT_SERVER"}
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=3600)
    if done.returncode != 0:
        lines = (done.stderr or done.stdout).strip().splitlines() or ["depict failed"]
        raise DepictError(lines[-1])
    return [line for line in done.stderr.splitlines() if line.startswith("depict: warning")]


def _multipart(fields, files):
    boundary = uuid.uuid4().hex
    body = bytearray()
    for name, value in fields.items():
        body += f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"\r\n\r\n'.encode()
        body += value.encode() + b"\r\n"
    for name, (filename, data) in files.items():
        kind = mimetypes.guess_type(filename)[0] or "application/octet-stream"
        body += (
            f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"; '
            f'filename="{filename}"\r\nContent-Type: {kind}\r\n\r\n'
        ).encode()
        body += data + b"\r\n"
    body += f"--{boundary}--\r\n".encode()
    return bytes(body), f"multipart/form-data; boundary={boundary}"


def run_server(url, src, out, camera, pipeline, name, view_layer):
    """POST /v1/enhance to a Depict server (Python's standard library only)."""
    with open(src, "rb") as fh, open(camera) as cam, open(pipeline) as pipe:
        files = {"file": (name, fh.read())}
        fields = {"camera": cam.read(), "pipeline": pipe.read(), "view_layer": view_layer}
    body, ctype = _multipart(fields, files)
    request = urllib.request.Request(url.rstrip("/") + "/v1/enhance", data=body, method="POST")
    request.add_header("Content-Type", ctype)
    key = os.environ.get("DEPICT_API_KEY")
    if key:
        request.add_header("Authorization", f"Bearer {key}")
    try:
        with urllib.request.urlopen(request, timeout=3600) as answer, open(out, "wb") as dst:
            shutil.copyfileobj(answer, dst)
    except urllib.error.HTTPError as exc:
        try:
            detail = json.loads(exc.read().decode()).get("detail", str(exc))
        except ValueError:
            detail = str(exc)
        raise DepictError(f"the Depict server refused: {detail}") from None
    except (urllib.error.URLError, OSError) as exc:
        raise DepictError(f"cannot reach the Depict server {url}: {exc}") from None
    return []


def load_result(path):
    """The image "Depict Result" on ``path`` (reloaded if it exists)."""
    image = bpy.data.images.get(RESULT_IMAGE)
    if image is None:
        image = bpy.data.images.load(path, check_existing=False)
        image.name = RESULT_IMAGE
    else:
        image.filepath = path
        image.reload()
    return image


def use_in_compositor(scene, image, view_layer):
    """An Image node of the result on ``view_layer`` (a render saved with the compositor on also
    holds a "Composite" layer), its Depict pass linked to the Composite (and Viewer) node."""
    scene.use_nodes = True
    tree = scene.node_tree
    node = tree.nodes.get(RESULT_NODE) or tree.nodes.new("CompositorNodeImage")
    node.name = node.label = RESULT_NODE
    node.image = image
    try:
        node.layer = view_layer
    except TypeError:  # a single-layer file: no choice to make
        pass
    socket = node.outputs.get("Depict")
    if socket is None:
        raise DepictError(f"the result has no Depict pass in the view layer {view_layer!r}")
    for kind in ("CompositorNodeComposite", "CompositorNodeViewer"):
        target = next((n for n in tree.nodes if n.bl_idname == kind), None)
        if target is None and kind == "CompositorNodeComposite":
            target = tree.nodes.new(kind)
        if target is not None:
            tree.links.new(socket, target.inputs[0])
    return node


def work_dir():
    """A new folder for one run's files: beside the saved .blend (``//depict/``), else in the
    system's temporary folder. Not Blender's own temporary folder: it goes when Blender quits,
    and the result image must stay."""
    if bpy.data.filepath:
        base = os.path.join(os.path.dirname(bpy.data.filepath), "depict")
        os.makedirs(base, exist_ok=True)
    else:
        base = tempfile.gettempdir()
    return tempfile.mkdtemp(prefix="depict-", dir=base)


def enhance(context, pipeline_text, render, compositor):
    """The whole operator (see the module docstring); returns (result path, warnings)."""
    scene = context.scene
    try:
        pipeline = json.loads(pipeline_text)
    except ValueError as exc:
        raise DepictError(f"the pipeline is not valid JSON: {exc}") from None
    if isinstance(pipeline, list):
        pipeline = {"steps": pipeline}
    folder = work_dir()
    src = os.path.join(folder, "render.exr")
    out = os.path.join(folder, "render_depict.exr")
    camera = os.path.join(folder, "camera.json")
    pipe = os.path.join(folder, "pipeline.json")
    save_render(ensure_render(context, render, "cryptomatte" in pipeline_text), scene, src)
    with open(camera, "w") as fh:
        json.dump(camera_json(scene), fh)
    with open(pipe, "w") as fh:
        json.dump(pipeline, fh)
    prefs = context.preferences.addons.get(__name__)
    prefs = prefs.preferences if prefs else None
    server = (prefs.server if prefs else "") or os.environ.get("DEPICT_SERVER", "")
    layer = context.view_layer.name  # (the one the user works on, of a render with several)
    if server:
        name = (bpy.path.basename(bpy.data.filepath) or "render").rsplit(".", 1)[0] + ".exr"
        warnings = run_server(server, src, out, camera, pipe, name, layer)
    else:
        warnings = run_local(find_executable(prefs), src, out, camera, pipe, layer)
    image = load_result(out)
    if compositor:
        use_in_compositor(scene, image, layer)
    return out, warnings


# -- operator and panels --------------------------------------------------------------------------


class DEPICT_OT_enhance(bpy.types.Operator):
    """Enhance the last render (or render the scene) with Depict"""

    bl_idname = "depict.enhance"
    bl_label = "Enhance with Depict"
    bl_options = {"REGISTER"}  # noqa: RUF012 (Blender's class attribute)

    pipeline: StringProperty(
        name="Pipeline",
        description="Depict pipeline JSON (empty: the panel's operator and parameters)",
        default="",
    )
    render: BoolProperty(name="Render first", default=False)
    compositor: BoolProperty(name="Use in compositor", default=False)

    def execute(self, context):
        settings = context.scene.depict
        text = self.pipeline or settings.pipeline_json()
        try:
            path, warnings = enhance(
                context,
                text,
                self.render or settings.render,
                self.compositor or settings.compositor,
            )
        except (DepictError, RuntimeError) as exc:
            self.report({"ERROR"}, str(exc).strip().splitlines()[-1])
            return {"CANCELLED"}
        for warning in warnings:
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, f"Depict: {RESULT_IMAGE} <- {path}")
        return {"FINISHED"}


def draw_settings(layout, settings):
    layout.prop(settings, "operator")
    op = settings.operator
    if op == "radiance_scaling":
        layout.prop(settings, "gamma")
        layout.prop(settings, "scenario")
    elif op == "light_alignment":
        layout.prop(settings, "lla_gamma")
        layout.prop(settings, "form")
    elif op == "unsharp_masking":
        layout.prop(settings, "amount")
    elif op == "apparent_relief":
        layout.prop(settings, "style")
    if op == "custom":
        layout.prop(settings, "pipeline", text="")
    else:
        layout.prop(settings, "mask")
    layout.prop(settings, "render")
    layout.prop(settings, "compositor")
    layout.operator(DEPICT_OT_enhance.bl_idname, icon="SHADING_RENDERED")


class DEPICT_PT_render(bpy.types.Panel):
    bl_label = "Depict"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"

    def draw(self, context):
        draw_settings(self.layout, context.scene.depict)


class DEPICT_PT_image(bpy.types.Panel):
    bl_label = "Depict"
    bl_space_type = "IMAGE_EDITOR"
    bl_region_type = "UI"
    bl_category = "Depict"

    def draw(self, context):
        draw_settings(self.layout, context.scene.depict)


CLASSES = (DepictPreferences, DepictSettings, DEPICT_OT_enhance, DEPICT_PT_render, DEPICT_PT_image)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.depict = PointerProperty(type=DepictSettings)


def unregister():
    del bpy.types.Scene.depict
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)


if __name__ == "__main__":
    register()
