"""Corpus scene ``rock``: a rock shaped by procedural displacement, and two pebbles, on sand.

Late-afternoon sun from the left (long cast shadows) under Blender's Nishita sky; the rock's
albedo is a noise texture, the sand's a finer one. Run by ``python -m bench.corpus render``
(``blender -b --factory-startup --python corpus/rock.py -- --out DIR --name NAME ...``).
"""

import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scenelib as lib

SUN = lib.sun_direction(elevation_deg=32.0, azimuth_deg=115.0)
STONE = ((0.3, (0.12, 0.1, 0.09)), (0.5, (0.3, 0.27, 0.24)), (0.7, (0.55, 0.52, 0.47)))
SAND = ((0.35, (0.36, 0.3, 0.22)), (0.65, (0.6, 0.53, 0.42)))


def rock(name: str, location, scale, seed: int, index: int, subdivisions: int = 6):
    """An icosphere displaced by two octaves of clouds (big lumps, then grit)."""
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=subdivisions, radius=1.0, location=location)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = scale
    for label, size, strength in (("lumps", 0.9, 0.45), ("grit", 0.12, 0.04)):
        tex = bpy.data.textures.new(f"{name}-{label}", type="CLOUDS")
        tex.noise_scale = size
        tex.noise_depth = 2
        tex.noise_basis = "VORONOI_F1" if label == "lumps" else "BLENDER_ORIGINAL"
        mod = obj.modifiers.new(label, "DISPLACE")
        mod.texture = tex
        mod.strength = strength
        mod.mid_level = 0.5
        mod.texture_coords = "LOCAL"
        tex.intensity = 1.0 + 0.05 * seed
    mat = lib.principled(f"{name}Mat", roughness=0.85)
    lib.ramp_albedo(mat, "ShaderNodeTexNoise", STONE, scale=1.5, Scale=3.0, Detail=8.0)
    lib.assign(obj, mat, index)
    lib.rest_on_floor(obj)
    obj.location.z -= 0.05 * scale[2]  # sink it a little, as rocks lie
    return obj


def main() -> None:
    args = lib.parse_args()
    lib.clear_scene()
    sand = lib.principled("Sand", roughness=0.9)
    lib.ramp_albedo(sand, "ShaderNodeTexNoise", SAND, scale=2.0, Scale=6.0, Detail=4.0)
    lib.add_floor(sand)
    rock("Rock", (0.0, 0.0, 0.0), (1.25, 1.0, 0.8), seed=0, index=2)
    rock("Pebble", (1.55, -0.9, 0.0), (0.32, 0.28, 0.22), seed=1, index=3, subdivisions=5)
    rock("Stone", (-1.6, -0.6, 0.0), (0.45, 0.4, 0.35), seed=2, index=4, subdivisions=5)
    world = lib.sky_world(elevation_deg=32.0, azimuth_deg=115.0, strength=0.15)
    sun = lib.add_sun(SUN, strength=2.5, angle_deg=1.5)
    cam = lib.add_camera(location=(0.8, -8.5, 1.7), target=(0.0, 0.0, 0.45))
    objects = {"Rock": 2, "Pebble": 3, "Stone": 4}
    lib.finish(args, cam, [sun], focus=(0.0, 0.0, 0.4), world=world, objects=objects)


main()
