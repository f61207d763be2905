# Blender extension entry point: forwards to the add-on package (see hud_addon/). Blender imports this
# folder as a package (bl_ext.<repository>.hud_tracer). Imported as a plain module (pytest collecting a
# checkout whose folder name is not a Python identifier, such as a CI clone), it defines nothing.
if __package__:
    from .hud_addon import register, unregister  # noqa: F401
