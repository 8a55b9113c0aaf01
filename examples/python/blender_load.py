"""Loads a skinpatch run's skin surface and deformed microstructure maps
into a Blender scene: the animated top surface (`surface.glb`, one shape
key per frame) with a material whose displacement follows the run's
height maps frame by frame.

Inside Blender (the run written with `[output] surface_glb = true` and a
`[microstructure]`):

    blender --python examples/python/blender_load.py -- out/press

Outside Blender the script only lists what it would load (the part that
needs no `bpy`):

    python examples/python/blender_load.py out/press

The 16-bit height PNGs store height = offset + value × scale in units of
`height_unit_um` µm (tEXt chunks); Blender reads the value as 0 … 1, so the
displacement node gets scale × 65535 × unit in scene units (mm, as the GLB
is written) and a midlevel that puts height 0 at the rest surface.
"""

import json
import pathlib
import re
import struct
import sys

MAP_NAME = re.compile(r"height_(\d{4,})\.png$")


def png_text(path):
    """The tEXt entries of a PNG file as a dict (keyword → text)."""
    data = pathlib.Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG file")
    entries, at = {}, 8
    while at + 8 <= len(data):
        (length,) = struct.unpack(">I", data[at : at + 4])
        kind = data[at + 4 : at + 8]
        body = data[at + 8 : at + 8 + length]
        if kind == b"tEXt":
            key, _, text = body.partition(b"\0")
            entries[key.decode("latin-1")] = text.decode("latin-1")
        if kind == b"IEND":
            break
        at += 12 + length
    return entries


def map_scaling(path):
    """(displacement scale, midlevel) for Blender's Displacement node from a
    height PNG's metadata: scene units (mm) per unit of the 0 … 1 value and
    the value at height 0."""
    text = png_text(path)
    try:
        offset = float(text["skinpatch:height_offset"])
        scale = float(text["skinpatch:height_scale"])
        unit_um = float(text.get("skinpatch:height_unit_um", "1"))
    except KeyError as missing:
        raise ValueError(f"{path}: no skinpatch height metadata ({missing})") from None
    span_mm = scale * 65535.0 * unit_um * 1e-3
    midlevel = -offset / (scale * 65535.0) if scale > 0 else 0.0
    return span_mm, midlevel


def collect(run_dir):
    """What a run folder offers Blender: the surface GLB, the neutral map,
    the deformed maps by frame, the frame rate and the displacement scaling.
    Raises FileNotFoundError naming what is missing."""
    run_dir = pathlib.Path(run_dir)
    summary_path = run_dir / "summary.json"
    if not summary_path.exists():
        raise FileNotFoundError(f"{summary_path}: not a skinpatch run folder (no summary.json)")
    summary = json.loads(summary_path.read_text())
    glb = run_dir / "surface.glb"
    if not glb.exists():
        raise FileNotFoundError(f"{glb}: run the scenario with [output] surface_glb = true")
    micro = run_dir / "micro"
    maps = sorted(
        (int(m.group(1)), p)
        for p in micro.glob("height_*.png")
        if (m := MAP_NAME.search(p.name))
    )
    neutral = micro / "height_neutral.png"
    plan = {
        "surface_glb": glb,
        "frame_rate_hz": float(summary["scenario"]["time"]["frame_rate_hz"]),
        "frames": len(summary["run"]["frames"]),
        "neutral_map": neutral if neutral.exists() else None,
        "maps": maps,
        "displacement": map_scaling(neutral) if neutral.exists() else None,
    }
    return plan


def load_into_blender(plan):
    """Builds the scene from `plan` (needs bpy)."""
    import bpy

    scene = bpy.context.scene
    # Shape keys are keyed at the frame times: match the run's rate first.
    scene.render.fps = round(plan["frame_rate_hz"])
    scene.render.fps_base = scene.render.fps / plan["frame_rate_hz"]
    scene.frame_start, scene.frame_end = 0, plan["frames"] - 1
    before = set(bpy.data.objects)
    bpy.ops.import_scene.gltf(filepath=str(plan["surface_glb"]))
    skin = [o for o in bpy.data.objects if o not in before and o.type == "MESH"]
    if not skin or plan["neutral_map"] is None:
        return skin
    images = {frame: bpy.data.images.load(str(path)) for frame, path in plan["maps"]}
    neutral = bpy.data.images.load(str(plan["neutral_map"]))
    for image in [neutral, *images.values()]:
        image.colorspace_settings.name = "Non-Color"
    material = bpy.data.materials.new("skinpatch skin")
    material.use_nodes = True
    material.cycles.displacement_method = "BOTH"
    nodes, links = material.node_tree.nodes, material.node_tree.links
    texture = nodes.new("ShaderNodeTexImage")
    texture.image = neutral
    texture.interpolation = "Cubic"
    displacement = nodes.new("ShaderNodeDisplacement")
    span_mm, midlevel = plan["displacement"]
    displacement.inputs["Scale"].default_value = span_mm
    displacement.inputs["Midlevel"].default_value = midlevel
    links.new(texture.outputs["Color"], displacement.inputs["Height"])
    output = nodes["Material Output"]
    links.new(displacement.outputs["Displacement"], output.inputs["Displacement"])
    for obj in skin:
        obj.data.materials.clear()
        obj.data.materials.append(material)

    def follow_maps(scene, *_):
        # The latest map at or before the frame (maps come every
        # microstructure.frame_stride frames).
        shown = [f for f in images if f <= scene.frame_current]
        texture.image = images[max(shown)] if shown else neutral

    bpy.app.handlers.frame_change_pre.append(follow_maps)
    follow_maps(scene)
    return skin


def main(argv):
    if len(argv) != 1:
        raise SystemExit("usage: blender_load.py RUN_DIR (after `--` inside Blender)")
    plan = collect(argv[0])
    try:
        import bpy  # noqa: F401
    except ImportError:
        print(f"surface: {plan['surface_glb']}")
        print(f"{plan['frames']} frames at {plan['frame_rate_hz']} Hz")
        print(f"neutral map: {plan['neutral_map']}")
        print(f"{len(plan['maps'])} deformed maps: frames {[f for f, _ in plan['maps']]}")
        if plan["displacement"]:
            print("displacement scale {:.6g} mm, midlevel {:.6g}".format(*plan["displacement"]))
        print("(outside Blender: nothing loaded)")
        return plan
    load_into_blender(plan)
    return plan


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    main(args)
