"""HUD Tracer for Blender: set up a HUD scene, render it with the tracer, get cd/m^2 back.

Import order, lowest to highest (as in BlendLuxCore): properties < export < engine < operators < ui.
Nothing but this file runs at import time, so that the package can be imported without bpy; the
modules load on register(). The add-on runs as a subpackage of the extension package
(bl_ext.<repo>.hud_tracer), beside the tracer and the presets, which it imports relatively.
"""

_MODULES: list = []


def register():
    from . import engine, operators, properties, ui

    _MODULES[:] = [properties, engine, operators, ui]
    for module in _MODULES:
        module.register()


def unregister():
    for module in reversed(_MODULES):
        module.unregister()
    _MODULES.clear()
