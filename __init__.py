# Blender extension entry point: forwards to the add-on package (see hud_addon/).
from .hud_addon import register, unregister  # noqa: F401
