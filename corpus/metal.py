"""Corpus scene ``metal``: glossy metals on a stone floor under an open sky.

A gold Suzanne (roughness 0.25), a chrome sphere (0.05: a mirror of the sky, the floor and its
neighbours) and a brushed copper torus (0.4, anisotropic) on a rough stone floor; a high sun
and Blender's Nishita sky, which the metals reflect. Run by ``python -m bench.corpus render``.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scenelib as lib

STONE = ((0.35, (0.2, 0.2, 0.19)), (0.65, (0.36, 0.35, 0.33)))


def main() -> None:
    args = lib.parse_args()
    lib.clear_scene()
    floor = lib.principled("Stone", roughness=0.8)
    lib.ramp_albedo(floor, "ShaderNodeTexNoise", STONE, scale=1.0, Scale=4.0, Detail=6.0)
    lib.add_floor(floor)
    gold = lib.principled("Gold", (1.0, 0.71, 0.29), roughness=0.25, Metallic=1.0)
    lib.add_suzanne("Suzanne", gold, 2, (0.0, 0.3, 0.0), size=1.4, rotation_deg=(0, 0, 10))
    chrome = lib.principled("Chrome", (0.95, 0.95, 0.95), roughness=0.05, Metallic=1.0)
    lib.add_sphere("Sphere", chrome, 3, (-1.45, -0.5, 0.0), radius=0.5)
    copper = lib.principled(
        "Copper", (0.95, 0.64, 0.54), roughness=0.4, Metallic=1.0, Anisotropic=0.6
    )
    lib.add_torus("Torus", copper, 4, (1.4, -0.6, 0.0), 0.5, 0.2, rotation_deg=(70, 0, -30))
    world = lib.sky_world(elevation_deg=55.0, azimuth_deg=-150.0, strength=0.15)
    sun = lib.add_sun(lib.sun_direction(55.0, -150.0), strength=2.5, angle_deg=1.0)
    cam = lib.add_camera(location=(0.3, -7.0, 2.4), target=(0.0, 0.0, 0.5))
    lib.finish(args, cam, [sun], (0.0, 0.0, 0.5), world, {"Suzanne": 2, "Sphere": 3, "Torus": 4})


main()
