"""Corpus scene ``spot``: Keenan Crane's cow (``examples/spot.obj``, CC0) on grass-green floor.

A character-like mesh, smooth-shaded and subdivided once, with black patches (thresholded
procedural noise) on its albedo; a warm backdrop wall beside it bounces light onto it. A
morning sun from the front left casts its shadow across the floor, a small area lamp adds a
key from the right, and Blender's Nishita sky fills. Run by ``python -m bench.corpus render``.
"""

import os
import sys

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import scenelib as lib  # noqa: E402

MESH = os.path.join(os.path.dirname(HERE), "examples", "spot.obj")
PATCHES = ((0.47, (0.03, 0.025, 0.02)), (0.5, (0.8, 0.78, 0.74)))
GRASS = ((0.3, (0.14, 0.2, 0.07)), (0.7, (0.26, 0.33, 0.12)))


def cow(index: int):
    bpy.ops.wm.obj_import(filepath=MESH, forward_axis="NEGATIVE_Z", up_axis="Y")
    obj = bpy.context.selected_objects[0]
    obj.name = "Spot"
    obj.scale = (1.3, 1.3, 1.3)
    obj.rotation_euler = (obj.rotation_euler[0], 0.0, 2.5)
    lib.subdivide(obj, 1)
    mat = lib.principled("Cow", roughness=0.55)
    lib.ramp_albedo(mat, "ShaderNodeTexNoise", PATCHES, scale=1.0, Scale=2.0, Detail=2.0)
    lib.assign(obj, mat, index)
    obj.location = (0.0, 0.0, 0.0)
    lib.rest_on_floor(obj)
    return obj


def main() -> None:
    args = lib.parse_args()
    lib.clear_scene()
    grass = lib.principled("Grass", roughness=0.9)
    lib.ramp_albedo(grass, "ShaderNodeTexNoise", GRASS, scale=1.0, Scale=8.0, Detail=6.0)
    lib.add_floor(grass)
    wall = lib.principled("Ochre", (0.7, 0.45, 0.15), roughness=0.9)
    lib.add_wall(wall, location=(2.3, 1.6, 1.0), rotation_deg=(90.0, 0.0, -25.0), size=2.5)
    cow(2)
    world = lib.sky_world(elevation_deg=28.0, azimuth_deg=-215.0, strength=0.15)
    sun = lib.add_sun(lib.sun_direction(28.0, -215.0), strength=2.5, angle_deg=1.5)
    key = lib.add_area((3.0, -3.5, 2.5), (0.0, 0.0, 0.6), power=150.0, size=1.0, name="Key")
    cam = lib.add_camera(location=(-0.5, -6.4, 2.0), target=(0.25, 0.0, 0.8))
    lib.finish(args, cam, [sun, key], (0.0, 0.0, 0.6), world, {"Spot": 2})


main()
