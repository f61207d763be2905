"""What every light-transport method shares: the film, the budget, the batch loop, the report data.

A method is a subclass of :class:`Integrator` registered by name (:func:`register`). It renders in
seed-addressed batches: batch k draws its random numbers from ``make_rng(seed, k)`` only, and its
results are added to a :class:`Film` whose sums merge exactly, so the same seeds give the same image
however batches are distributed (over processes, later over machines). Progress and cancellation
cross into the tracer as two callables, ``progress(fraction, message)`` and ``should_stop()``,
checked once per batch.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..accel import Accelerator
from ..apertures import DiskTarget, MeshTarget
from ..eye import ThinLensEye
from ..optics.surfaces import Interaction, Surface, make_surface
from ..sampling import make_rng
from ..scene import Scene
from ..units import luminance
from ..vec import dot, norm, rows

#: Rays per batch (structure of arrays, one Embree call per bounce).
DEFAULT_BATCH = 1 << 17

#: Russian roulette (Arvo & Kirk 1990, doi:10.1145/97880.97886) starts at this depth and only for
#: paths whose weight fell below this fraction of where it started, surviving with probability
#: weight / ROULETTE_WEIGHT. A plain "survive with the weight" rule would turn the LCD's 5 %
#: transmission into 20x fireflies on every later windshield bounce (the ghost image).
ROULETTE_DEPTH = 6
ROULETTE_WEIGHT = 1e-5

Progress = Callable[[float, str], None]
ShouldStop = Callable[[], bool]


@dataclass
class Budget:
    """Stop after ``rays`` ray segments or ``seconds`` of wall time, whichever comes first."""

    rays: int | None = None
    seconds: float | None = None

    def __post_init__(self):
        if self.rays is None and self.seconds is None:
            raise ValueError("a budget needs rays or seconds")
        if self.rays is not None and self.rays <= 0:
            raise ValueError("rays must be positive")
        if self.seconds is not None and self.seconds <= 0:
            raise ValueError("seconds must be positive")

    def fraction(self, rays: int, seconds: float) -> float:
        parts = []
        if self.rays is not None:
            parts.append(rays / self.rays)
        if self.seconds is not None:
            parts.append(seconds / self.seconds)
        return min(1.0, max(parts))


class Film:
    """Per-pixel sums of a Monte Carlo estimator of apparent luminance (cd/m^2).

    The estimate of pixel i is ``sum_rgb[i] / samples``: ``samples`` counts independent primary
    samples per pixel (backward) or particles emitted (forward); every sample adds its value to one
    pixel at most. ``sum_y2`` holds the sum of squared luminance values for the variance of the mean.
    """

    def __init__(self, width: int, height: int):
        self.width, self.height = width, height
        n = width * height
        self.sum_rgb = np.zeros((n, 3))
        self.sum_y2 = np.zeros(n)
        self.samples = 0

    def add(self, pixels: np.ndarray, values: np.ndarray):
        """Add sample values (m, 3) RGB cd/m^2 to flat pixel indices (m,)."""
        if len(pixels) == 0:
            return
        n = self.width * self.height
        for c in range(3):
            self.sum_rgb[:, c] += np.bincount(pixels, weights=values[:, c], minlength=n)
        y = luminance(values)
        self.sum_y2 += np.bincount(pixels, weights=y * y, minlength=n)

    def merge(self, other: Film):
        self.sum_rgb += other.sum_rgb
        self.sum_y2 += other.sum_y2
        self.samples += other.samples

    def rgb(self) -> np.ndarray:
        """(H, W, 3) mean apparent luminance, linear Rec.709, cd/m^2."""
        s = max(self.samples, 1)
        return (self.sum_rgb / s).reshape(self.height, self.width, 3)

    def variance_y(self) -> np.ndarray:
        """(H, W) variance of the pixel's mean luminance, (cd/m^2)^2."""
        s = max(self.samples, 1)
        mean_y = luminance(self.sum_rgb) / s
        var = np.maximum(self.sum_y2 / s - mean_y**2, 0.0) / s
        return var.reshape(self.height, self.width)


@dataclass
class RenderResult:
    """The outcome of one render: the film plus the figures that go into report.json."""

    method: str
    seed: int
    film: Film
    rays: int
    paths: int
    found: int
    seconds: float
    partial: bool
    batches: int
    warnings: list[str] = field(default_factory=list)
    extra: dict = field(default_factory=dict)

    @property
    def efficiency(self) -> float:
        """Paths that carried light to the retina (forward) or found a source (backward) / paths."""
        return self.found / self.paths if self.paths else 0.0

    @property
    def rays_per_second(self) -> float:
        return self.rays / self.seconds if self.seconds > 0 else 0.0


INTEGRATORS: dict[str, type[Integrator]] = {}


def register(cls):
    """Class decorator: make a method available by its ``name`` (CLI, scene files, add-on)."""
    INTEGRATORS[cls.name] = cls
    return cls


class Integrator:
    """Base of all methods. Subclasses implement :meth:`run_batch`."""

    name = ""
    summary = ""

    def __init__(self, scene: Scene, seed: int, batch_size: int = DEFAULT_BATCH):
        self.scene = scene
        self.seed = int(seed)
        self.batch_size = int(batch_size)
        self.eye = ThinLensEye(scene.eye)
        self.objects = scene.traced_objects
        self.surfaces: list[Surface] = [make_surface(o) for o in self.objects]
        self.accel = Accelerator([(o.vertices, o.faces) for o in self.objects]) if self.objects else None
        self.warnings: list[str] = []
        self.rays_without_geometry = 0  # rays of a scene with no geometry: they all escape
        self.truncated = 0  # paths cut at max_depth (a bias the report warns of)
        self._targets: dict[str, DiskTarget | MeshTarget] = {}

    # -- helpers shared by the methods ---------------------------------------------------------
    def target(self, name: str):
        """The aiming target "eye" (the pupil disk) or a named planar object."""
        if name not in self._targets:
            if name == "eye":
                self._targets[name] = DiskTarget(self.eye.position, self.eye.gaze, self.eye.pupil_radius)
            else:
                self._targets[name] = MeshTarget(self.scene.object(name).triangles)
        return self._targets[name]

    def interaction(self, slot: int, hits, idx: np.ndarray, dirs: np.ndarray) -> Interaction:
        """Surface data for rays ``idx`` that hit object ``slot``: shading normals and UVs are
        interpolated from the vertices with the hits' barycentrics (computed only for objects that
        have vertex normals or texture coordinates)."""
        obj = self.objects[slot]
        ng = rows(hits.normals, idx)
        ns, uv = ng, None
        if obj.normals is not None or obj.uv is not None:
            face = obj.faces[hits.face[idx]]
            bary = hits.bary(idx)
            u, v = bary[:, 0], bary[:, 1]
            w0 = 1.0 - u - v
            if obj.normals is not None:
                nv = obj.normals
                ns = w0[:, None] * nv[face[:, 0]] + u[:, None] * nv[face[:, 1]] + v[:, None] * nv[face[:, 2]]
                ns /= np.maximum(norm(ns), 1e-300)[:, None]
                ns = np.where((dot(ns, ng) < 0)[:, None], -ns, ns)
            if obj.uv is not None:
                t = obj.uv
                uv = w0[:, None] * t[face[:, 0]] + u[:, None] * t[face[:, 1]] + v[:, None] * t[face[:, 2]]
        return Interaction(rows(dirs, idx), rows(hits.points, idx), ng, ns, uv)

    @property
    def rays_traced(self) -> int:
        n = self.accel.rays_traced if self.accel else self.rays_without_geometry
        return n + sum(t._accel.rays_traced for t in self._targets.values() if isinstance(t, MeshTarget))

    # -- the batch loop ----------------------------------------------------------------------------
    def run_batch(self, rng: np.random.Generator, film: Film) -> tuple[int, int]:
        """Trace one batch into ``film``; return (paths, paths that found light)."""
        raise NotImplementedError

    def trace_batch(self, index: int) -> tuple:
        """Trace batch ``index`` into a film of its own: (index, sum_rgb, sum_y2, samples, paths,
        found, rays, truncated), what :func:`drive` merges, in this process or in a worker."""
        film = Film(self.eye.width, self.eye.height)
        rays_before, truncated_before = self.rays_traced, self.truncated
        paths, found = self.run_batch(make_rng(self.seed, index), film)
        return (index, film.sum_rgb, film.sum_y2, film.samples, paths, found, self.rays_traced - rays_before,
                self.truncated - truncated_before)

    def render(self, budget: Budget, progress: Progress | None = None,
               should_stop: ShouldStop | None = None) -> RenderResult:
        """Render in this process: the batches run one at a time through the same driver, and the
        same merge, as on several processes (tracer.parallel) or a cluster (tracer.distributed)."""
        return drive(self, budget, lambda k: _Done(self.trace_batch(k)), 1, progress, should_stop)

    def finish(self, result: RenderResult):
        """Add method-specific warnings and figures to a finished result."""
        if result.found == 0:
            result.warnings.append(
                f"no light path found: {result.method} traced {result.paths:,} paths ({result.rays:,} rays) and "
                f"none reached {'the retina' if result.method == 'forward' else 'a source'} "
                f"(efficiency {result.efficiency:.3g}); the image is black because the method failed, "
                "not because the scene is dark")
        elif result.found < 100:
            result.warnings.append(
                f"only {result.found} of {result.paths:,} paths found light (efficiency {result.efficiency:.3g}): "
                "the image is dominated by noise")


class _Done:
    """A batch traced in this process, with the interface of a pending task."""

    def __init__(self, value):
        self._value = value

    def done(self) -> bool:
        return True

    def result(self):
        return self._value


def drive(local: Integrator, budget: Budget, submit, in_flight: int, progress: Progress | None = None,
          should_stop: ShouldStop | None = None, label: str = "") -> RenderResult:
    """Hand out batch indices in increasing order through ``submit(k)`` (which returns an object with
    ``done()`` and ``result()``, the tuple of :meth:`Integrator.trace_batch`), keep at most
    ``in_flight`` running, and merge the contiguous prefix of finished batches in batch order until
    the budget is met. Each batch fills its own film and films are added in batch order, so one
    process, several, or a cluster give the same image for a budget in rays."""
    method = f"{local.name} {label}" if label else local.name
    done: dict[int, tuple] = {}
    pending: dict[int, object] = {}
    film = Film(local.eye.width, local.eye.height)
    rays = paths = found = truncated = merged = next_index = 0
    first = (0.0, 0)  # (seconds, rays) when the first batch was merged: start-up and warm-up end there
    partial = False
    start = time.perf_counter()
    while True:
        budget_met = budget.fraction(rays, time.perf_counter() - start) >= 1.0
        if should_stop is not None and not budget_met and should_stop():
            partial = True
            break
        if budget_met:
            break  # batches still in flight would land beyond the budget: dropped, not awaited
        while len(pending) < in_flight:
            pending[next_index] = submit(next_index)
            next_index += 1
        finished = [k for k, f in pending.items() if f.done()]
        if not finished:
            time.sleep(0.002)
            continue
        for k in finished:
            done[k] = pending.pop(k).result()
        while merged in done and budget.fraction(rays, time.perf_counter() - start) < 1.0:
            _, s_rgb, s_y2, samples, p, f, r, t = done.pop(merged)
            film.sum_rgb += s_rgb
            film.sum_y2 += s_y2
            film.samples += samples
            paths, found, rays, truncated = paths + p, found + f, rays + r, truncated + t
            merged += 1
            if merged == 1:
                first = (time.perf_counter() - start, rays)
            if progress is not None:
                elapsed = time.perf_counter() - start
                eff = found / paths if paths else 0.0
                progress(budget.fraction(rays, elapsed),
                         f"{method}: {rays:,} rays, efficiency {eff:.2e}, {elapsed:.1f} s")
        if rays == 0 and merged > 0:
            break  # nothing to trace (no source, no geometry): more batches cannot help
    result = RenderResult(local.name, local.seed, film, rays, paths, found, time.perf_counter() - start, partial,
                          merged, list(local.warnings))
    if merged > 1 and result.seconds > first[0]:
        result.extra["steady_rays_per_second"] = (rays - first[1]) / (result.seconds - first[0])
    local.truncated = truncated
    local.finish(result)
    return result
