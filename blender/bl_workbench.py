"""The look of the headless renders (``bl_screenshot.py``, ``bl_rig_screenshot.py``): the
Workbench engine as the viewport's solid shading, materials' colours, a light grey world, and
a camera for the scene."""
import bpy


def workbench(scene, width: int, height: int, lens: float):
    """Set ``scene`` to render ``width`` x ``height`` with Workbench; its new camera."""
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light, scene.display.shading.color_type = "STUDIO", "MATERIAL"
    scene.display.shading.show_shadows = False
    scene.world = bpy.data.worlds.new("bg")
    scene.world.color = (0.92, 0.92, 0.92)
    scene.render.resolution_x, scene.render.resolution_y = width, height
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    camera.data.lens = lens
    scene.camera = camera
    return camera
