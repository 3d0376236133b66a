"""Corpus scene ``still_life``: Suzanne and a torus on a checker floor before a red wall.

Textures on the albedo: Blender's generated colour-grid image on Suzanne (through its UVs),
procedural wave bands on the torus, a procedural checker on the floor. A sun from the front
right casts the shadows, a large area lamp fills from the left, the sky is a gradient, and the
red wall bleeds its colour on the floor and the objects (indirect light). Run by
``python -m bench.corpus render``.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scenelib as lib

BANDS = ((0.4, (0.08, 0.22, 0.45)), (0.6, (0.75, 0.72, 0.62)))


def main() -> None:
    args = lib.parse_args()
    lib.clear_scene()
    floor = lib.principled("Checker", roughness=0.7)
    lib.checker_albedo(floor, (0.55, 0.55, 0.52), (0.22, 0.22, 0.21), scale=1.5)
    lib.add_floor(floor)
    lib.add_wall(
        lib.principled("RedWall", (0.55, 0.06, 0.04), roughness=0.9),
        location=(-1.3, 2.8, 1.5),
        rotation_deg=(90.0, 0.0, 10.0),
        size=3.0,
    )
    grid = lib.principled("Grid", roughness=0.45)
    lib.image_albedo(grid, "ColourGrid")
    lib.add_suzanne("Suzanne", grid, 2, (-0.55, 0.2, 0.0), size=1.4, rotation_deg=(0, 0, 15))
    bands = lib.principled("Bands", roughness=0.35)
    lib.ramp_albedo(
        bands, "ShaderNodeTexWave", BANDS, scale=1.0, Scale=2.5, Distortion=2.0, Detail=3.0
    )
    lib.add_torus("Torus", bands, 3, (1.15, -0.35, 0.0), 0.55, 0.22, rotation_deg=(62, 0, 25))
    world = lib.gradient_world((0.55, 0.6, 0.65), (0.12, 0.22, 0.45), strength=0.6)
    sun = lib.add_sun(lib.sun_direction(45.0, -140.0), strength=2.5, angle_deg=1.0)
    fill = lib.add_area((-4.0, -3.0, 2.5), (0.0, 0.0, 0.5), power=120.0, size=2.5, name="Fill")
    cam = lib.add_camera(location=(0.9, -6.8, 2.6), target=(0.2, 0.0, 0.55))
    lib.finish(args, cam, [sun, fill], (0.2, 0.0, 0.5), world, objects={"Suzanne": 2, "Torus": 3})


main()
