"""Pilots: short renders that tell which method suits a channel of the image (the hybrid and auto
methods, :mod:`tracer.methods.hybrid`), and which methods apply to it at all.

A pilot is scored by its efficiency 1 / (V x cost), cost its seconds (a budget in seconds) or ray
segments (a budget in rays, which makes the choice reproducible); V is the largest of four medians of
a pixel's relative variance over :data:`STRATA` of the pilots' combined image (a pixel the method
left dark counts as infinitely noisy), so that a method must be good at every level of the image, the
typical pixel as well as the brightest.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ..core.kept import KeptResults
from ..core.units import luminance
from ..transport.chains import specular_paths
from .base import DEFAULT_BATCH, SMALLEST_BATCH, Integrator

#: Paths per pilot batch (a backward batch covers every pixel a whole number of times).
PILOT_BATCH = 1 << 14


#: Most pixels of a pilot's retina: the pilots of a larger retina run on a coarser one (:func:`pilot_world`).
PILOT_PIXELS = 1 << 16


def pilot_world(world):
    """The world in which a channel's pilots run: ``world``, or, where its retina has more than
    :data:`PILOT_PIXELS` pixels, the same with a coarser retina of the same field of view (at most
    that many pixels, the aspect kept). Pilots compare methods by V x cost, and every method's
    per-pixel variance grows with the pixel count in the same proportion (its samples, particles or
    photons spread over the pixels: backward 1 / spp = pixels / N, forward and photon pixels / N
    through the pixel's area and the footprint-sized gather radius), so the choice made on the coarse
    retina holds at full size, while the pilots of a 4K retina cost what those of 256 x 256 do (a pass
    over every pixel per pilot batch took minutes there)."""
    eye = world.eye
    pixels = eye.width * eye.height
    if pixels <= PILOT_PIXELS:
        return world
    f = math.sqrt(PILOT_PIXELS / pixels)
    coarse = (max(1, int(eye.width * f)), max(1, int(eye.height * f)))
    return world.with_eye(dataclasses.replace(eye.spec, resolution=coarse))


#: A pilot runs at least this many batches and until its film holds this many replicates.
MIN_PILOT_BATCHES, MIN_PILOT_REPLICATES, MAX_PILOT_BATCHES = 2, 4, 64


#: Pixels darker than this share of the brightest pilot pixel are left out of the efficiency.
LIT_SHARE = 1e-4


#: Seed offset of a channel's pilot streams, so that no pilot shares a stream with a render.
PILOT_SEED = 7919


@dataclass
class Pilot:
    """One method's pilot on one channel: what it cost (``cost`` in the budget's unit: seconds, or ray
    segments for a budget in rays), what it found, and its efficiency 1 / (V x cost)."""

    method: str
    skipped: str | None = None
    seconds: float = 0.0
    rays: int = 0
    paths: int = 0
    found: int = 0
    batches: int = 0
    batch_size: int = 0
    replicates: int = 0
    cost: float = 0.0
    #: V (the largest of the medians of a pixel's relative variance over :data:`STRATA`) and the medians
    #: by stratum (:func:`relative_variances`).
    relative_variance: float | None = None
    relative_variance_medians: dict | None = None
    efficiency: float = 0.0
    #: The method's units of work in the pilot (paths of a backward batch, else its batch size: particles
    #: or photons) and, summed over the pixels, its image's variance (cd/m^2)^2 times those units: what
    #: one unit of work is worth, for the allocation between channels (variance falls as 1 / units).
    units: int = 0
    variance_units: float = 0.0
    image: np.ndarray | None = field(default=None, repr=False)
    variance: np.ndarray | None = field(default=None, repr=False)

    def summary(self) -> dict:
        """The pilot for the report (JSON: an infinite median, where the pilot left most of a stratum's
        pixels dark, is given as null, with a note naming the strata)."""
        out = {k: v for k, v in asdict(self).items() if k not in ("image", "variance")}
        medians = out["relative_variance_medians"] or {}
        dark = [name for name, v in medians.items() if not math.isfinite(v)]
        out["relative_variance_medians"] = {name: (v if math.isfinite(v) else None) for name, v in medians.items()} \
            if medians else None
        if out["relative_variance"] is not None and not math.isfinite(out["relative_variance"]):
            out["relative_variance"] = None
        if dark:
            out["note"] = (f"most pixels of {', '.join(dark)} (of the pixels that some pilot lit) stayed dark in "
                           "this one: efficiency 0")
        return out


def applicable(world, lights: bool, environment: bool) -> dict[str, str | None]:
    """{method: None where it applies to a channel of ``world`` keeping these sources, else why not}."""
    out: dict[str, str | None] = {"backward": None}
    lit_env = environment and not world.environment.is_black
    if not lights or len(world.lights) == 0:
        out["forward"] = "forward tracing emits from the scene's emitters only, and this channel has none"
        out["photon"] = "photons leave the scene's emitters only, and this channel has none"
        return out
    if lit_env:
        out["forward"] = "forward tracing does not render the environment (the hybrid method gives it a channel)"
        out["photon"] = "the photon method does not carry environment light (the hybrid method gives it a channel)"
        return out
    out["forward"] = None
    blocked = world.accel is not None and KEPT_BLOCKED.get(
        (*world.key, len(world.lights)), lambda: bool(specular_paths(world, environment=False)["specular_blockers"]))
    out["photon"] = None if blocked else PHOTON_NOT_NEEDED
    return out


#: Whether a specular object blocks the emitters' light to a scattering surface in view, by the world's
#: key (and its emitters): the chief-ray survey behind :func:`applicable` is the scene's and the eye's
#: alone, and it costs a second at large retinas, so auto and hybrid ask it once per scene and eye in a
#: process (F12 after F12 in Blender).
KEPT_BLOCKED = KeptResults(16)


#: Why the pilots leave the photon method out where next-event estimation reaches every scattering
#: surface in view. It would still render such a channel right (its connections take the direct light,
#: its photons the rest), so a channel given the photon method is rendered with it all the same.
PHOTON_NOT_NEEDED = ("every scattering surface the eye sees is lit straight from the emitters (or there is none): "
                     "next-event estimation reaches them, photon maps are not needed")


#: Seconds of a time budget's pilot share (``pilot_share`` x the budget) under which ``auto`` chooses by
#: :func:`rule_choice` instead of pilots. The pilots need a few whole batches of every method that applies
#: (1.8 s on hud-direct, 7.8 s on hud-screen, 2 cores), so that on a short budget they took the time of the
#: render itself and more (auto on hud-screen with 2 s: 9.3 s of pilots, 0.2 s of render, 12 s of wall time).
PILOT_FLOOR_SECONDS = 2.0


def rule_choice(candidates: dict[str, str | None]) -> tuple[str, str]:
    """The method the rules give a channel whose ``candidates`` ({method: None where it applies, else why
    not}, :func:`applicable`) leave a choice, and why: the photon method where it applies (the quadrature
    finds specular optics between a scattering surface in view and the emitters, which next-event
    estimation cannot connect through), else backward tracing with next-event estimation. (A screen lit
    only through a mirror fold behind an absorbing baffle names no specular blocker: backward, which
    renders it right by sampling the screen's law.) The pilots confirm both on the presets (hud-direct:
    backward; hud-direct-condenser and hud-screen: photon; tests/methods/test_pilots.py), and neither rule
    picks forward tracing, which wins only where the eye sees small emitters through optics that a
    backward path reaches by chance."""
    if candidates.get("photon", "") is None:
        return "photon", ("specular optics stand between a scattering surface in view and the emitters (photon maps "
                          "reach it, next-event estimation does not)")
    return "backward", ("no specular optics stand between a scattering surface in view and the emitters (next-event "
                        "estimation reaches it)")


#: The strata a pilot is judged on: the brightest of these shares of the lit pixels (of the pilots'
#: combined image), each at least STRATUM_PIXELS pixels; "lit" is all of them.
STRATA = {"lit": 1.0, "brightest_half": 0.5, "brightest_tenth": 0.1, "brightest_hundredth": 0.01}


STRATUM_PIXELS = 8


def combined_image(images: list[np.ndarray], variances: list[np.ndarray]) -> np.ndarray:
    """The pilots' luminance images (cd/m^2) combined per pixel with inverse-variance weights, each
    pilot counted only where it lit the pixel (a dark pixel says nothing of its luminance); a pilot
    whose estimate there has no spread (every replicate the same) weighs as if its relative variance
    were 1e-12."""
    num = np.zeros(images[0].shape)
    den = np.zeros(images[0].shape)
    for y, var in zip(images, variances, strict=True):
        w = np.zeros(y.shape)
        np.divide(1.0, np.maximum(var, 1e-12 * y * y), out=w, where=y > 0)
        num += w * y
        den += w
    out = np.zeros(images[0].shape)
    np.divide(num, den, out=out, where=den > 0)
    return out


def relative_variances(images: list[np.ndarray], variances: list[np.ndarray], k: int) -> dict[str, float] | None:
    """The medians of var / mean^2 of pilot ``k`` over each of :data:`STRATA` (module docstring), a
    pixel that pilot ``k`` left dark counted as infinite: the pixels any pilot lit, and the brightest
    half, tenth and hundredth of them in the pilots' :func:`combined_image`. None where no pilot lit
    anything. V, the figure the efficiency divides by, is the largest."""
    brightest = max((float(y.max()) for y in images), default=0.0)
    if brightest <= 0:
        return None
    lit = np.zeros(images[0].shape, bool)
    for y in images:
        lit |= y > LIT_SHARE * brightest
    y, var = images[k][lit], variances[k][lit]
    rel = np.full(y.shape, np.inf)
    np.divide(var, y * y, out=rel, where=y > 0)
    order = np.argsort(-combined_image(images, variances)[lit], kind="stable")  # brightest first
    out = {}
    for name, share in STRATA.items():
        n = min(len(order), max(STRATUM_PIXELS, math.ceil(share * len(order))))
        out[name] = float(np.median(rel[order[:n]]))
    return out


def pilot_batch_size(method: str, pixels: int) -> int:
    """A pilot's batch: PILOT_BATCH paths; for the backward method a whole number of passes over the
    pixels (its batches trace one sample per pixel per pass); for the photon method its default batch
    (an eye pass per batch costs the same whatever its photons: a small batch would misstate what a
    photon costs and is worth)."""
    if method == "backward":
        return max(SMALLEST_BATCH, pixels * max(1, round(PILOT_BATCH / pixels)))
    if method == "photon":
        return DEFAULT_BATCH
    return PILOT_BATCH


def run_pilot(integrator: Integrator, method: str, seconds: float | None, rays: int | None, in_rays: bool) -> Pilot:
    """Trace pilot batches of ``integrator`` (seeded on a pilot stream) until its share of the budget
    (``seconds`` or ``rays``) is spent and its film holds enough replicates. ``in_rays``: the cost is
    counted in ray segments (a budget in rays), else in seconds."""
    t0 = time.perf_counter()
    fresh = not integrator.has_reference
    integrator.reference_luminance  # noqa: B018  (its roulette pilot: part of its cost)
    # its rays counted whether traced now or kept from an earlier render (tracer.methods.base.KEPT_PILOTS),
    # so that a budget in rays leaves the same to the render either way
    rays0 = integrator.world.rays_traced - (integrator.pilot_rays if fresh else 0)
    film = integrator.new_film()
    paths = found = k = 0
    while k < MAX_PILOT_BATCHES:
        b = integrator.trace_batch(k)
        film.merge_arrays(b.film)
        paths, found, k = paths + b.paths, found + b.found, k + 1
        if k >= MIN_PILOT_BATCHES and film.replicates >= MIN_PILOT_REPLICATES and (
                (seconds is not None and time.perf_counter() - t0 >= seconds) or
                (rays is not None and integrator.world.rays_traced - rays0 >= rays)):
            break
    spent_s, spent_r = time.perf_counter() - t0, integrator.world.rays_traced - rays0
    var = film.variance_y()
    units = paths if method == "backward" else k * integrator.batch_size
    return Pilot(method, None, spent_s, spent_r, paths, found, k, integrator.batch_size, film.replicates,
                 float(spent_r) if in_rays else spent_s, image=luminance(film.rgb()), variance=var, units=units,
                 variance_units=float(var.sum()) * units)
