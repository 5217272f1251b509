"""Run by Blender's Python (bpy): re-write a .glb with Blender's own glTF exporter.

    $WORKBENCH_BPY_PYTHON blender_gltf_export.py SOURCE.glb OUT.glb [draco]

Imports SOURCE with Blender's importer (objects with parents and transforms,
shape keys, the shape-key action), shades every mesh smooth (as a face is;
flat shading would make the exporter split every vertex per triangle), and
exports with Blender's exporter: shape keys as morph targets with
``extras.targetNames``, object transforms as nodes, the action sampled per
frame (24 fps) as ``weights`` channels; with ``draco``, the meshes
Draco-compressed (14-bit positions, Blender's default).
"""

import sys

import bpy

src, out = sys.argv[sys.argv.index("--") + 1 : sys.argv.index("--") + 3] if "--" in sys.argv else sys.argv[1:3]
draco = "draco" in sys.argv[3:]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=src)
for obj in bpy.data.objects:
    if obj.type == "MESH":
        obj.data.shade_smooth()
kw = {
    "filepath": out,
    "export_format": "GLB",
    "export_morph": True,
    "export_animations": True,
    "export_normals": True,
}
if draco:
    kw["export_draco_mesh_compression_enable"] = True
bpy.ops.export_scene.gltf(**kw)
print("EXPORTED", out)
