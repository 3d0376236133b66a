"""What every corpus scene shares: materials, floor, world, lights, camera, passes and sidecars.

Blender's own Python imports this module (bpy and mathutils only; the scene scripts beside it put
this folder on ``sys.path``). A scene script builds its objects with these helpers and ends with
:func:`finish`, which renders one frame and writes, into ``--out``:

* ``NAME.exr``: Cycles multilayer OpenEXR, 32-bit float, ZIP, layer ``ViewLayer``, with every
  pass Depict reads (Combined, Depth, Normal, Position, DiffDir/Ind/Col, GlossDir/Ind/Col,
  TransDir/Ind/Col, AO, Emit, Env) plus ``IndexOB`` (the object index: 0 background, 1 floor
  and backdrop, 2, 3, … one per object);
* ``NAME.camera.json``: Depict's camera JSON (``world_to_camera``, ``fov_y_deg`` from the
  projection matrix Blender renders with, ``projection``);
* ``NAME.lights.json``: the key lights in camera space as Depict light strings (``"X,Y,Z"``,
  the direction towards the light, ``*W`` its irradiance relative to the first), with their
  world-space description and the object indices.

Arguments (after Blender's ``--``): ``--out DIR --name NAME --width W --height H --samples S
[--threads N] [--seed N]``. Renders are deterministic: fixed seed, no animated seed, no adaptive
sampling, no denoising.
"""

import argparse
import json
import math
import os
import sys

import bpy
from mathutils import Vector

#: Object index of the floor and backdrop surfaces (``IndexOB``); objects count from 2.
FLOOR_INDEX = 1
#: Focal length and vertical sensor size (sensor fit VERTICAL: every size frames the same height).
LENS_MM = 50.0
SENSOR_MM = 24.0

_PASSES = (
    "use_pass_combined",
    "use_pass_z",
    "use_pass_normal",
    "use_pass_position",
    "use_pass_object_index",
    "use_pass_diffuse_direct",
    "use_pass_diffuse_indirect",
    "use_pass_diffuse_color",
    "use_pass_glossy_direct",
    "use_pass_glossy_indirect",
    "use_pass_glossy_color",
    "use_pass_transmission_direct",
    "use_pass_transmission_indirect",
    "use_pass_transmission_color",
    "use_pass_ambient_occlusion",
    "use_pass_emit",
    "use_pass_environment",
)


def parse_args() -> argparse.Namespace:
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
    ap = argparse.ArgumentParser(prog="blender -b --factory-startup --python SCENE.py --")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--name", required=True, help="file stem of the frame")
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--threads", type=int, default=0, help="render threads (0: all cores)")
    ap.add_argument("--seed", type=int, default=0)
    return ap.parse_args(argv)


def clear_scene() -> None:
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)
    for coll in (bpy.data.meshes, bpy.data.materials, bpy.data.lights, bpy.data.cameras):
        for block in list(coll):
            coll.remove(block)


# -- materials -----------------------------------------------------------------------------------


def principled(name, color=(0.8, 0.8, 0.8), roughness=0.5, **inputs):
    """A Principled BSDF material; ``inputs`` set other sockets by name (``Metallic=1.0``)."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    for key, value in inputs.items():
        bsdf.inputs[key].default_value = value
    return mat


def _bsdf(mat):
    return mat.node_tree.nodes["Principled BSDF"]


def _link(mat, src, dst) -> None:
    mat.node_tree.links.new(src, dst)


def _object_coords(mat, scale: float):
    """Object-space texture coordinates scaled by ``scale`` (a Mapping node's output)."""
    nodes = mat.node_tree.nodes
    coords = nodes.new("ShaderNodeTexCoord")
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (scale, scale, scale)
    _link(mat, coords.outputs["Object"], mapping.inputs["Vector"])
    return mapping.outputs["Vector"]


def checker_albedo(mat, color1, color2, scale: float) -> None:
    """Procedural checker on the base colour (object coordinates, ``scale`` squares per unit)."""
    tex = mat.node_tree.nodes.new("ShaderNodeTexChecker")
    tex.inputs["Color1"].default_value = (*color1, 1.0)
    tex.inputs["Color2"].default_value = (*color2, 1.0)
    tex.inputs["Scale"].default_value = 1.0
    _link(mat, _object_coords(mat, scale), tex.inputs["Vector"])
    _link(mat, tex.outputs["Color"], _bsdf(mat).inputs["Base Color"])


def ramp_albedo(mat, texture: str, stops, scale: float, **settings) -> None:
    """A procedural texture (``ShaderNodeTexNoise``, ``…Voronoi``, ``…Wave``) through a colour
    ramp (``stops``: (position, RGB) pairs) on the base colour."""
    nodes = mat.node_tree.nodes
    tex = nodes.new(texture)
    for key, value in settings.items():
        if key in tex.inputs:
            tex.inputs[key].default_value = value
        else:
            setattr(tex, key, value)
    ramp = nodes.new("ShaderNodeValToRGB")
    elements = ramp.color_ramp.elements
    while len(elements) < len(stops):
        elements.new(0.5)
    for element, (pos, rgb) in zip(elements, stops, strict=True):
        element.position = pos
        element.color = (*rgb, 1.0)
    _link(mat, _object_coords(mat, scale), tex.inputs["Vector"])
    out = tex.outputs["Fac"] if "Fac" in tex.outputs else tex.outputs["Distance"]
    _link(mat, out, ramp.inputs["Fac"])
    _link(mat, ramp.outputs["Color"], _bsdf(mat).inputs["Base Color"])


def image_albedo(mat, name: str, size: int = 512) -> None:
    """Blender's generated colour-grid image (an image texture, no file) on the base colour,
    through the mesh's UVs."""
    image = bpy.data.images.new(name, width=size, height=size)
    image.generated_type = "COLOR_GRID"
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = "Linear"
    _link(mat, tex.outputs["Color"], _bsdf(mat).inputs["Base Color"])


# -- objects -------------------------------------------------------------------------------------


def assign(obj, mat, index: int, smooth: bool = True):
    """Give ``obj`` the material ``mat``, the object index ``index`` and smooth/flat shading."""
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    for poly in obj.data.polygons:
        poly.use_smooth = smooth
    obj.pass_index = index
    return obj


def subdivide(obj, levels: int = 2) -> None:
    mod = obj.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = levels
    mod.render_levels = levels


def _placed(obj, name: str, mat, index: int, smooth: bool = True, levels: int = 0):
    obj.name = name
    if levels:
        subdivide(obj, levels)
    assign(obj, mat, index, smooth)
    rest_on_floor(obj)
    return obj


def add_suzanne(name, mat, index, location, size=1.0, rotation_deg=(0.0, 0.0, 0.0)):
    """Blender's monkey head, subdivided twice and smooth, resting on the floor."""
    rot = tuple(math.radians(a) for a in rotation_deg)
    bpy.ops.mesh.primitive_monkey_add(size=size, location=location, rotation=rot)
    return _placed(bpy.context.active_object, name, mat, index, levels=2)


def add_torus(name, mat, index, location, major, minor, rotation_deg=(0.0, 0.0, 0.0)):
    """A smooth torus (its UVs come with it), resting on the floor."""
    rot = tuple(math.radians(a) for a in rotation_deg)
    bpy.ops.mesh.primitive_torus_add(
        major_radius=major,
        minor_radius=minor,
        major_segments=96,
        minor_segments=36,
        location=location,
        rotation=rot,
    )
    return _placed(bpy.context.active_object, name, mat, index)


def add_sphere(name, mat, index, location, radius):
    """A smooth UV sphere resting on the floor."""
    bpy.ops.mesh.primitive_uv_sphere_add(
        segments=96, ring_count=48, radius=radius, location=location
    )
    return _placed(bpy.context.active_object, name, mat, index)


def add_floor(mat, size: float = 60.0):
    """A flat floor plane at z = 0 (index :data:`FLOOR_INDEX`)."""
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0.0, 0.0, 0.0))
    floor = bpy.context.active_object
    floor.name = "Floor"
    return assign(floor, mat, FLOOR_INDEX, smooth=False)


def add_wall(mat, location, rotation_deg, size: float):
    """A flat backdrop (counted with the floor, index :data:`FLOOR_INDEX`)."""
    rot = tuple(math.radians(a) for a in rotation_deg)
    bpy.ops.mesh.primitive_plane_add(size=size, location=location, rotation=rot)
    wall = bpy.context.active_object
    wall.name = "Wall"
    return assign(wall, mat, FLOOR_INDEX, smooth=False)


def rest_on_floor(obj) -> None:
    """Move ``obj`` so the lowest point of its evaluated mesh touches z = 0."""
    bpy.context.view_layer.update()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    lowest = min((evaluated.matrix_world @ v.co).z for v in mesh.vertices)
    evaluated.to_mesh_clear()
    obj.location.z -= lowest


# -- world and lights ----------------------------------------------------------------------------


def _world():
    world = bpy.data.worlds.get("World") or bpy.data.worlds.new("World")
    bpy.context.scene.world = world
    world.use_nodes = True
    world.light_settings.distance = 1.0  # AO distance, scene units
    return world


def sun_direction(elevation_deg: float, azimuth_deg: float) -> Vector:
    """World direction towards a sun at ``elevation_deg`` above the horizon, ``azimuth_deg``
    from +Y towards −X (the convention of the Nishita sky's ``sun_rotation``)."""
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return Vector((-math.cos(e) * math.sin(a), math.cos(e) * math.cos(a), math.sin(e)))


def sky_world(elevation_deg: float, azimuth_deg: float, strength: float) -> dict:
    """Blender's Nishita sky without its sun disc (the sun lamp casts the sharp shadows)."""
    world = _world()
    nodes = world.node_tree.nodes
    sky = nodes.new("ShaderNodeTexSky")
    sky.sky_type = "NISHITA"
    sky.sun_disc = False
    sky.sun_elevation = math.radians(elevation_deg)
    sky.sun_rotation = math.radians(azimuth_deg)
    bg = nodes["Background"]
    bg.inputs["Strength"].default_value = strength
    world.node_tree.links.new(sky.outputs["Color"], bg.inputs["Color"])
    return {"type": "nishita_sky", "sun_elevation_deg": elevation_deg, "strength": strength}


def gradient_world(horizon, zenith, strength: float) -> dict:
    """A sky gradient: ``horizon`` colour at and below the horizon, ``zenith`` straight up."""
    world = _world()
    nodes = world.node_tree.nodes
    coords = nodes.new("ShaderNodeTexCoord")
    xyz = nodes.new("ShaderNodeSeparateXYZ")
    ramp = nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (*horizon, 1.0)
    ramp.color_ramp.elements[1].color = (*zenith, 1.0)
    links = world.node_tree.links
    links.new(coords.outputs["Generated"], xyz.inputs["Vector"])
    links.new(xyz.outputs["Z"], ramp.inputs["Fac"])
    bg = nodes["Background"]
    bg.inputs["Strength"].default_value = strength
    links.new(ramp.outputs["Color"], bg.inputs["Color"])
    return {"type": "gradient", "horizon": list(horizon), "zenith": list(zenith)}


def add_sun(direction: Vector, strength: float, angle_deg: float = 1.0, name: str = "Sun"):
    """A sun lamp shining from ``direction`` (world, towards the light)."""
    data = bpy.data.lights.new(name, type="SUN")
    data.energy = strength
    data.angle = math.radians(angle_deg)
    sun = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(sun)
    sun.rotation_euler = direction.to_track_quat("Z", "Y").to_euler()
    return sun


def add_area(location, target, power: float, size: float, name: str = "Area"):
    """A square area lamp of ``power`` watts at ``location`` aimed at ``target``."""
    data = bpy.data.lights.new(name, type="AREA")
    data.energy = power
    data.shape = "SQUARE"
    data.size = size
    lamp = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(lamp)
    lamp.location = location
    lamp.rotation_euler = (Vector(target) - lamp.location).to_track_quat("-Z", "Y").to_euler()
    return lamp


# -- camera and render ---------------------------------------------------------------------------


def add_camera(location, target):
    data = bpy.data.cameras.new("Camera")
    data.type = "PERSP"
    data.lens = LENS_MM
    data.sensor_fit = "VERTICAL"
    data.sensor_height = SENSOR_MM
    data.clip_start = 0.05
    data.clip_end = 200.0
    cam = bpy.data.objects.new("Camera", data)
    bpy.context.scene.collection.objects.link(cam)
    cam.location = location
    cam.rotation_euler = (Vector(target) - cam.location).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = cam
    return cam


def configure_render(args: argparse.Namespace) -> str:
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    cyc = scene.cycles
    cyc.device = "CPU"
    cyc.samples = args.samples
    cyc.seed = args.seed
    cyc.use_animated_seed = False
    cyc.use_adaptive_sampling = False
    cyc.use_denoising = False
    cyc.max_bounces = 12
    cyc.transmission_bounces = 12
    cyc.sample_clamp_indirect = 10.0  # Blender's default: fireflies stay, as in production
    render = scene.render
    render.resolution_x, render.resolution_y = args.width, args.height
    render.resolution_percentage = 100
    render.pixel_aspect_x = render.pixel_aspect_y = 1.0
    render.film_transparent = False
    render.use_border = False
    render.threads_mode = "FIXED" if args.threads > 0 else "AUTO"
    if args.threads > 0:
        render.threads = args.threads
    scene.view_settings.view_transform = "Standard"  # the EXR is scene-linear either way
    scene.frame_set(1)
    layer = bpy.context.view_layer
    layer.name = "ViewLayer"
    for attr in _PASSES:
        setattr(layer, attr, True)
    settings = render.image_settings
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    settings.exr_codec = "ZIP"
    settings.use_preview = False
    render.use_file_extension = True
    render.filepath = os.path.join(args.out, args.name + ".exr")
    return render.filepath


def camera_json(cam, width: int, height: int) -> dict:
    """Depict's camera JSON; the vertical fov comes from the projection matrix Blender renders
    with (``cam.data.angle_y`` is the sensor's angle, not the image's)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    proj = cam.calc_matrix_camera(depsgraph, x=width, y=height, scale_x=1.0, scale_y=1.0)
    world_to_camera = cam.matrix_world.inverted()
    return {
        "world_to_camera": [[v + 0.0 for v in row] for row in world_to_camera],
        "fov_y_deg": math.degrees(2.0 * math.atan(1.0 / proj[1][1])),
        "projection": "perspective",
    }


def _towards(lamp, focus: Vector) -> tuple[Vector, float]:
    """World direction towards ``lamp`` from ``focus`` and its irradiance there (W/m², facing
    the lamp; an area lamp as a Lambertian emitter P/π W/sr, approximate)."""
    data = lamp.data
    if data.type == "SUN":
        d = lamp.matrix_world.to_3x3() @ Vector((0.0, 0.0, 1.0))
        return d.normalized(), float(data.energy)
    offset = lamp.matrix_world.translation - focus
    dist2 = offset.length_squared
    d = offset.normalized()
    facing = lamp.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))
    cos_lamp = max(0.0, facing.normalized().dot(-d))
    scale = cos_lamp / math.pi if data.type == "AREA" else 1.0 / (4.0 * math.pi)
    return d, float(data.energy) * scale / dist2


def lights_json(cam, lamps, focus) -> dict:
    """The key lights in camera space (Depict light strings, the first unweighted)."""
    w2c = cam.matrix_world.inverted().to_3x3()
    focus = Vector(focus)
    strings, sources = [], []
    key = None
    for lamp in lamps:
        d_world, irradiance = _towards(lamp, focus)
        d_cam = (w2c @ d_world).normalized()
        key = irradiance if key is None else key
        text = ",".join(f"{v:.4f}" for v in d_cam)
        if lamp is not lamps[0]:
            text += f"*{irradiance / key:.3f}"
        strings.append(text)
        sources.append(
            {
                "name": lamp.name,
                "type": lamp.data.type,
                "power": float(lamp.data.energy),
                "direction_to_light_world": list(d_world),
                "direction_to_light_camera": list(d_cam),
                "irradiance_at_focus": irradiance,
            }
        )
    return {"lights": strings, "focus_world": list(focus), "sources": sources}


def _write_json(path: str, data: dict) -> None:
    with open(path, "w") as fh:
        json.dump(data, fh, indent=1)
        fh.write("\n")


def finish(args, cam, lamps, focus, world: dict, objects: dict) -> None:
    """Render the frame and write its camera and lights beside it (see the module docstring).
    ``lamps``: key light first; ``focus``: where the lamps' directions are taken (world);
    ``objects``: name -> object index, recorded in the lights file."""
    os.makedirs(args.out, exist_ok=True)
    exr = configure_render(args)
    bpy.context.view_layer.update()
    stem = os.path.join(args.out, args.name)
    _write_json(stem + ".camera.json", camera_json(cam, args.width, args.height))
    info = lights_json(cam, lamps, focus)
    info.update(
        {
            "world": world,
            "object_index": {"background": 0, "floor": FLOOR_INDEX, **objects},
            "render": {
                "blender": bpy.app.version_string,
                "size": [args.width, args.height],
                "samples": args.samples,
                "seed": args.seed,
            },
        }
    )
    _write_json(stem + ".lights.json", info)
    bpy.ops.render.render(write_still=True)
    print(f"wrote {exr}")
