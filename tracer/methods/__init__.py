"""Light-transport methods, found by name: ``INTEGRATORS["forward"]``, ``INTEGRATORS["backward"]``,
``"photon"``, ``"hybrid"``, ``"auto"``. A method registers itself and appears in the command line and
the Blender add-on without changes there.
"""

from ..core.film import Film
from . import backward, forward, hybrid, photon  # noqa: F401  (registration)
from .base import DEFAULT_BATCH, INTEGRATORS, Budget, Integrator, RenderResult

#: The method used when none is named: backward tracing with next-event estimation, the most
#: time-efficient where the scattering surfaces see the LEDs directly (docs/results/accuracy.md), with
#: no pilot to pay for. "auto" chooses per scene and "hybrid" per channel, by pilots
#: of a few seconds (tracer/methods/hybrid.py).
DEFAULT_METHOD = "backward"

__all__ = ["DEFAULT_BATCH", "DEFAULT_METHOD", "INTEGRATORS", "Budget", "Film", "Integrator", "RenderResult"]
