"""Render a Blender frame with a known camera, to check the camera Depict solves from it.

Run with Blender (Debian's 3.4.1 was used)::

    blender -b --factory-startup --python tests/blender/camera_frame.py -- OUT.exr CAM.json \\
        WIDTH HEIGHT PERSP|ORTHO [SENSOR_FIT] [LENS_MM|ORTHO_SCALE] [SAMPLES]

A ground plane, a sphere, Suzanne and a cube seen by a camera off every axis; Cycles with one
sample (no denoising), a multilayer EXR with Combined, Depth, Normal and Position. ``CAM.json`` is
the true camera in Depict's camera JSON form: ``world_to_camera`` = the inverse of the camera's
``matrix_world``, and the vertical field of view (or ortho height) of the whole frame from
Blender's own projection matrix (``calc_matrix_camera``), so the sensor-fit rules are Blender's.
"""

import json
import math
import sys

import bpy
from mathutils import Vector


def args() -> list:
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
    if len(argv) < 5:
        raise SystemExit(__doc__)
    return argv


def build(projection: str, fit: str, size: float) -> object:
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)
    shapes = (  # add, its size, location, colour, smooth (subdivided)
        (bpy.ops.mesh.primitive_plane_add, {"size": 12.0}, (0, 0, 0), (0.6, 0.6, 0.55), False),
        (
            bpy.ops.mesh.primitive_uv_sphere_add,
            {"radius": 0.6},
            (0.3, -0.5, 0.6),
            (0.2, 0.4, 0.8),
            True,
        ),
        (
            bpy.ops.mesh.primitive_monkey_add,
            {"size": 1.2},
            (-1.1, 0.6, 0.8),
            (0.8, 0.45, 0.15),
            True,
        ),
        (bpy.ops.mesh.primitive_cube_add, {"size": 0.7}, (1.4, 0.9, 0.35), (0.7, 0.7, 0.7), False),
    )
    for add, extent, location, colour, smooth in shapes:
        add(location=location, **extent)
        obj = bpy.context.active_object
        material = bpy.data.materials.new(obj.name)
        material.use_nodes = True
        bsdf = material.node_tree.nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
        obj.data.materials.append(material)
        if smooth:
            obj.modifiers.new("Subdivision", "SUBSURF").levels = 2
            for poly in obj.data.polygons:
                poly.use_smooth = True
    light = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", type="SUN"))
    light.data.energy = 3.0
    bpy.context.scene.collection.objects.link(light)
    light.rotation_euler = (0.9, 0.3, 0.6)
    data = bpy.data.cameras.new("Camera")
    data.type = projection
    data.sensor_fit = fit
    if projection == "ORTHO":
        data.ortho_scale = size
    else:
        data.lens = size
    cam = bpy.data.objects.new("Camera", data)
    bpy.context.scene.collection.objects.link(cam)
    cam.location = (3.1, -5.2, 2.9)
    aim = Vector((0.1, 0.2, 0.5)) - cam.location
    cam.rotation_euler = aim.to_track_quat("-Z", "Y").to_euler()
    cam.rotation_euler.y += 0.05  # a little roll: no axis of the camera is aligned with the world
    bpy.context.scene.camera = cam
    return cam


def configure(out: str, width: int, height: int, samples: int) -> None:
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    vl = bpy.context.view_layer
    for attr in ("use_pass_combined", "use_pass_z", "use_pass_normal", "use_pass_position"):
        setattr(vl, attr, True)
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    settings.exr_codec = "ZIP"
    scene.render.filepath = out


def true_camera(cam: object, width: int, height: int) -> dict:
    bpy.context.view_layer.update()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    proj = cam.calc_matrix_camera(depsgraph, x=width, y=height)
    out = {"world_to_camera": [list(row) for row in cam.matrix_world.inverted()]}
    if cam.data.type == "ORTHO":
        out.update(projection="orthographic", ortho_height=2.0 / proj[1][1])
    else:
        out.update(projection="perspective", fov_y_deg=math.degrees(2 * math.atan(1 / proj[1][1])))
    out["blender_angle_y_deg"] = math.degrees(cam.data.angle_y)  # the trap: the sensor's angle
    return out


def main() -> None:
    a = args()
    out, cam_json, width, height, projection = a[0], a[1], int(a[2]), int(a[3]), a[4]
    fit = a[5] if len(a) > 5 else "AUTO"
    size = float(a[6]) if len(a) > 6 else (6.0 if projection == "ORTHO" else 35.0)
    samples = int(a[7]) if len(a) > 7 else 1
    cam = build(projection, fit, size)
    configure(out, width, height, samples)
    with open(cam_json, "w") as fh:
        json.dump(true_camera(cam, width, height), fh, indent=2)
    bpy.ops.render.render(write_still=True)


if __name__ == "__main__":
    main()
