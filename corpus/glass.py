"""Corpus scene ``glass``: solid and thin glass before coloured objects on a checker floor.

A solid glass sphere (IOR 1.45, smooth: refraction and caustics, its shadow mostly caustic), a
solid glass Suzanne (slightly rough), and a thin frosted pane (one surface, so the sun reaches
through it by next-event estimation), with a diffuse orange torus and a blue cube behind them
to be seen through the glass. Sun from behind-left (caustics fall towards the camera) and a
gradient sky. Run by ``python -m bench.corpus render``.
"""

import math
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scenelib as lib


def glass(name: str, roughness: float):
    return lib.principled(name, (0.95, 1.0, 0.97), roughness=roughness, Transmission=1.0, IOR=1.45)


def main() -> None:
    args = lib.parse_args()
    lib.clear_scene()
    floor = lib.principled("Checker", roughness=0.7)
    lib.checker_albedo(floor, (0.6, 0.6, 0.58), (0.12, 0.12, 0.12), scale=2.0)
    lib.add_floor(floor)
    lib.add_sphere("GlassSphere", glass("Glass", 0.0), 2, (-1.0, -0.6, 0.0), radius=0.55)
    lib.add_suzanne(
        "GlassSuzanne",
        glass("FrostedGlass", 0.15),
        3,
        (0.55, -0.3, 0.0),
        size=1.2,
        rotation_deg=(0, 0, 20),
    )
    bpy.ops.mesh.primitive_plane_add(
        size=1.0, location=(1.75, -1.0, 0.5), rotation=(math.radians(90.0), 0.0, 0.35)
    )
    pane = bpy.context.active_object
    pane.name = "Pane"
    pane.scale = (0.8, 1.0, 1.0)
    lib.assign(pane, glass("Pane", 0.3), 4, smooth=False)
    orange = lib.principled("Orange", (0.85, 0.35, 0.08), roughness=0.5)
    lib.add_torus("Torus", orange, 5, (-0.6, 1.1, 0.0), 0.55, 0.2, rotation_deg=(75, 0, 10))
    bpy.ops.mesh.primitive_cube_add(size=0.7, location=(1.9, 0.8, 0.35), rotation=(0, 0, 0.5))
    cube = bpy.context.active_object
    cube.name = "Cube"
    lib.assign(cube, lib.principled("Blue", (0.1, 0.2, 0.7), roughness=0.4), 6, smooth=False)
    world = lib.gradient_world((0.6, 0.62, 0.65), (0.2, 0.3, 0.5), strength=0.5)
    sun = lib.add_sun(lib.sun_direction(40.0, 30.0), strength=3.0, angle_deg=1.0)
    cam = lib.add_camera(location=(0.4, -7.2, 2.2), target=(0.2, 0.0, 0.5))
    objects = {"GlassSphere": 2, "GlassSuzanne": 3, "Pane": 4, "Torus": 5, "Cube": 6}
    lib.finish(args, cam, [sun], (0.0, 0.0, 0.5), world, objects)


main()
