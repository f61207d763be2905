"""Layer 1, basics: errors, units, (3, n) vector helpers, sampling routines, JSON and field checks, the
schema of settable fields, image files and the film. Nothing here knows optics or scenes."""
