"""A small scene made in Blender and written by Blender's own COLLADA exporter, as a user would:
Suzanne on a floor with a back wall, a point lamp, coloured materials, the default camera aimed
at her. Run: blender -b --factory-startup -P scripts/blender_suzanne.py -- OUT.dae (scripts/validate-unseen.sh does)"""
import sys
import bpy

out = sys.argv[sys.argv.index("--") + 1]
bpy.ops.wm.read_factory_settings(use_empty=True)

def material(name, rgb):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    m.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*rgb, 1.0)
    m.diffuse_color = (*rgb, 1.0)
    return m

bpy.ops.mesh.primitive_monkey_add(size=1.0, location=(0, 0, 0.6))
monkey = bpy.context.object
bpy.ops.object.modifier_add(type="SUBSURF")
monkey.modifiers["Subdivision"].levels = 2
bpy.ops.object.modifier_apply(modifier="Subdivision")
monkey.rotation_euler = (0.3, 0, 0.4)
monkey.data.materials.append(material("skin", (0.8, 0.45, 0.2)))
bpy.ops.mesh.primitive_plane_add(size=4.0, location=(0, 0, -0.3))
bpy.context.object.data.materials.append(material("floor", (0.6, 0.6, 0.6)))
bpy.ops.mesh.primitive_plane_add(size=4.0, location=(0, 2, 1.7), rotation=(1.5708, 0, 0))
bpy.context.object.data.materials.append(material("wall", (0.2, 0.3, 0.6)))
lamp = bpy.data.lights.new("lamp", type="POINT")
lamp.energy = 8
lo = bpy.data.objects.new("lamp", lamp)
lo.location = (1.5, -1.5, 3.0)
bpy.context.scene.collection.objects.link(lo)
cam = bpy.data.cameras.new("camera")
co = bpy.data.objects.new("camera", cam)
co.location = (0, -6, 2.0)
co.rotation_euler = (1.35, 0, 0)
bpy.context.scene.collection.objects.link(co)
bpy.context.scene.camera = co
bpy.ops.wm.collada_export(filepath=out, apply_modifiers=True, triangulate=True)
print("wrote", out)
