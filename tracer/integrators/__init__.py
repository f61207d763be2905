"""Light-transport methods, found by name: ``INTEGRATORS["forward"]``, ``INTEGRATORS["backward"]``.

Later methods (photon maps, the hybrid) register themselves the same way and appear in the
command line and the Blender add-on without changes there.
"""

from ..film import Film
from . import backward, forward  # noqa: F401  (registration)
from .base import DEFAULT_BATCH, INTEGRATORS, Budget, Integrator, RenderResult

__all__ = ["DEFAULT_BATCH", "INTEGRATORS", "Budget", "Film", "Integrator", "RenderResult"]
