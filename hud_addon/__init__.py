"""The Blender add-on (a skeleton in this release; the add-on issue fills it in).

It will export Blender scenes to the tracer's scene format (tracer/scene.py), the one seam between
Blender and the tracer, and run the tracer with progress and cancel passed as two callables.
register() and unregister() are safe to call without bpy-side state.
"""

_CLASSES: tuple = ()


def register():
    """Register the add-on's classes (none yet)."""
    import bpy

    for cls in _CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    import bpy

    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
