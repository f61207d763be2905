"""hud-tracer: forward, backward (and later bidirectional and hybrid) stochastic ray tracing of
head-up displays in photometric units, after Potemin, Zhdanov et al., "Hybrid ray tracing method for
photorealistic image synthesis in head-up displays", Proc. SPIE 10690, 106900I (2018),
doi:10.1117/12.2312589.

This package never imports bpy and uses relative imports only, so that the same code runs bundled
inside the Blender extension.
"""

__version__ = "0.1.0"
