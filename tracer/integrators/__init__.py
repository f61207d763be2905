"""Light-transport methods, found by name: ``INTEGRATORS["forward"]``, ``INTEGRATORS["backward"]``.

Later methods (photon maps, the hybrid) register themselves the same way and appear in the
command line and the Blender add-on without changes there.
"""

from ..film import Film
from . import backward, forward, hybrid, photon  # noqa: F401  (registration)
from .base import DEFAULT_BATCH, INTEGRATORS, Budget, Integrator, RenderResult

#: The method used when none is named: backward tracing with next-event estimation, the most
#: time-efficient on every preset (README, "Speed against accuracy"). The automatic choice of a method
#: per scene (a later issue) replaces this constant.
DEFAULT_METHOD = "backward"

__all__ = ["DEFAULT_BATCH", "DEFAULT_METHOD", "INTEGRATORS", "Budget", "Film", "Integrator", "RenderResult"]
