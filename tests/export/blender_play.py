"""Run inside Blender (``blender -b --factory-startup --python blender_play.py -- IN.glb OUT.json
K1 K2 ...``): import a myoface glTF export with Blender's own glTF importer, play its
animation to keyframes K1, K2, ... (indices of the skin's weight keyframes) and write what
Blender shows there: the skin's vertices with the shape keys applied (object space, metres,
Blender's axes), its basis (rest) vertices, and the world matrices of the head's objects."""

import json
import sys

import bpy
import numpy as np

# Debian 12's Blender 3.4.1 runs on Debian's NumPy 1.24, which removed the aliases np.bool,
# np.int, ... that this Blender's glTF importer still uses (set_poly_smoothing: np.bool): put
# them back (they were the builtins)
for _name, _type in (("bool", bool), ("int", int), ("float", float), ("object", object)):
    if _name not in np.__dict__:
        setattr(np, _name, _type)

args = sys.argv[sys.argv.index("--") + 1 :]
src, dst, keys = args[0], args[1], [int(k) for k in args[2:]]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=src)
scene = bpy.context.scene
skin = bpy.data.objects["skin"]
sk = skin.data.shape_keys
out = {
    "fps": scene.render.fps,
    "n_shape_keys": len(sk.key_blocks) - 1 if sk else 0,
    "shape_key_names": [kb.name for kb in sk.key_blocks[1:]] if sk else [],
    "basis": [list(v.co) for v in (sk.key_blocks[0].data if sk else skin.data.vertices)],
    "frames": [],
}
# where Blender put each keyframe of the weights (the importer's seconds x fps)
frames = sorted({p.co[0] for fc in sk.animation_data.action.fcurves for p in fc.keyframe_points})
out["n_keyframes"] = len(frames)
for k in keys:
    f = frames[k]
    scene.frame_set(int(f // 1), subframe=float(f % 1))
    dg = bpy.context.evaluated_depsgraph_get()
    ev = skin.evaluated_get(dg)
    mesh = ev.to_mesh()
    verts = [list(v.co) for v in mesh.vertices]
    ev.to_mesh_clear()
    mats = {
        name: [list(r) for r in bpy.data.objects[name].matrix_world]
        for name in ("myoface_head", "skin", "eye_l", "eye_r", "teeth_lower", "tongue")
        if name in bpy.data.objects
    }
    values = [kb.value for kb in sk.key_blocks[1:]]
    out["frames"].append(
        {"key": k, "frame": f, "skin": verts, "matrix_world": mats, "weights": values}
    )
with open(dst, "w") as fh:
    json.dump(out, fh)
