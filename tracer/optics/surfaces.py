"""Optical surfaces: what happens to a batch of rays that hits one material.

Every surface works on a whole batch (structure of arrays). ``scatter`` draws the outgoing direction
and returns the factor by which the path weight is multiplied (the BSDF times the cosine over the
sampling pdf), so each routine is an unbiased estimator of its own scattering law; the unit tests
check energy conservation (and reciprocity where it applies) against closed forms.

Transport modes (Veach 1997, ch. 5, "non-symmetric scattering"): backward paths carry radiance
from the eye (``radiance=True``); forward paths carry flux from the sources. Only refraction differs:
radiance crossing into a denser medium is scaled by (n_i / n_t)^2 on camera paths only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..sampling import (
    cosine_hemisphere,
    frame_from_normal,
    gaussian_lobe,
    gaussian_lobe_pdf,
    to_local,
    to_world,
)
from ..scene import SceneObject, emitter_luminance
from ..units import luminance
from ..vec import scale
from .fresnel import dot, fresnel_unpolarized, reflect, refract


@dataclass
class Interaction:
    """Rays (n of them) that hit one surface.

    d : (n, 3) unit incoming directions. p : (n, 3) hit points, mm. ng : (n, 3) unit geometric
    normals (mesh winding). ns : (n, 3) unit shading normals (interpolated, same side as ng).
    uv : (n, 2) texture coordinates or None.
    """

    d: np.ndarray
    p: np.ndarray
    ng: np.ndarray
    ns: np.ndarray
    uv: np.ndarray | None
    #: A surface's local frames at these hits, kept so that scatter, pdf and eval_fcos on the same
    #: interaction build them once.
    frame: tuple | None = None

    def __len__(self) -> int:
        return len(self.d)


def _side(it: Interaction) -> np.ndarray:
    """+1 where the ray arrives on the front (normal) side, -1 on the back side; (n,)."""
    return np.where(dot(it.d, it.ng) < 0, 1.0, -1.0)


def mirror_directions(it: Interaction) -> np.ndarray:
    """Specular reflection about the shading normal; where an interpolated normal would send the
    ray through the mesh, about the geometric normal instead. (n, 3)."""
    out = reflect(it.d, it.ns)
    wrong = dot(out, it.ng) * dot(it.d, it.ng) > 0
    if np.any(wrong):
        out[wrong] = reflect(it.d[wrong], it.ng[wrong])
    return out


class Surface:
    """Base class. ``specular`` surfaces pass rays on deterministically or by Fresnel choice;
    ``scattering`` ones also evaluate their BSDF and pdf for the directed split (paper sec. 2)."""

    kind = "surface"
    scattering = False
    emits = False
    terminal = False  # the path ends here (absorber, emitter)

    def __init__(self, obj: SceneObject):
        self.obj = obj
        self.name = obj.name

    def scatter(self, it: Interaction, rng: np.random.Generator, radiance: bool):
        raise NotImplementedError

    def branches(self, it: Interaction) -> list:
        """Deterministic specular branches [(directions (n, 3), RGB factor (n, 3), name)],
        for the brightness-theorem analysis (:mod:`tracer.analysis`); specular surfaces only."""
        raise NotImplementedError


class Absorber(Surface):
    """Black: every ray ends here."""

    kind = "absorber"
    terminal = True

    def scatter(self, it, rng, radiance):
        n = len(it)
        return it.d, np.zeros((n, 3)), np.zeros(n, bool)


class Mirror(Surface):
    """Ideal mirror of RGB reflectance R, reflecting on both sides about the shading normal."""

    kind = "mirror"

    def __init__(self, obj):
        super().__init__(obj)
        self.r = obj.material.params["reflectance"]

    def scatter(self, it, rng, radiance):
        n = len(it)
        return mirror_directions(it), np.broadcast_to(self.r, (n, 3)).copy(), np.ones(n, bool)

    def branches(self, it):
        return [(mirror_directions(it), np.tile(self.r, (len(it), 1)), "reflect")]


class Dielectric(Surface):
    """Smooth interface between ``ior_outside`` (front, normal side) and ``ior`` (back side).

    Reflection or refraction is chosen with the Fresnel probability, so the weight is 1 in flux
    mode and (n_i / n_t)^2 after refraction in radiance mode; total internal reflection reflects.
    """

    kind = "dielectric"

    def __init__(self, obj):
        super().__init__(obj)
        p = obj.material.params
        self.n_in, self.n_out = p["ior"], p["ior_outside"]

    def _geometry(self, it: Interaction):
        side = _side(it)
        n_face = scale(it.ns, side)  # normal on the incident side
        n_i = np.where(side > 0, self.n_out, self.n_in)
        n_t = np.where(side > 0, self.n_in, self.n_out)
        cos_i = np.clip(-dot(it.d, n_face), 0.0, 1.0)
        r, cos_t = fresnel_unpolarized(cos_i, n_t / n_i)
        return side, n_face, n_i, n_t, cos_i, r, cos_t

    def scatter(self, it, rng, radiance):
        side, n_face, n_i, n_t, cos_i, r, cos_t = self._geometry(it)
        refl = rng.random(len(it)) < r
        out = np.where(refl[:, None], reflect(it.d, n_face), refract(it.d, n_face, n_t / n_i, cos_i, cos_t))
        # Keep the outgoing ray on the side the event says (shading normals can disagree with ng).
        want = np.where(refl, side, -side)
        bad = np.sign(dot(out, it.ng)) != want
        if np.any(bad):
            out[bad] = np.where(refl[bad][:, None], reflect(it.d[bad], it.ng[bad]), it.d[bad])
        w = np.ones(len(it))
        if radiance:
            w = np.where(refl, 1.0, (n_i / n_t) ** 2)
        return out, np.repeat(w[:, None], 3, axis=1), np.ones(len(it), bool)

    def branches(self, it: Interaction):
        side, n_face, n_i, n_t, cos_i, r, cos_t = self._geometry(it)
        return [(reflect(it.d, n_face), np.repeat(r[:, None], 3, axis=1), "reflect"),
                (refract(it.d, n_face, n_t / n_i, cos_i, cos_t), np.repeat(1.0 - r[:, None], 3, axis=1), "refract")]


class Coating(Surface):
    """Coated thin partial reflector: reflects with R, transmits undeviated with T, absorbs the rest."""

    kind = "coating"

    def __init__(self, obj):
        super().__init__(obj)
        p = obj.material.params
        self.r, self.t = p["reflectance"], p["transmittance"]
        yr, yt = float(luminance(self.r)), float(luminance(self.t))
        self.p_reflect = yr / (yr + yt) if yr + yt > 0 else 0.0

    def scatter(self, it, rng, radiance):
        n = len(it)
        if self.p_reflect == 0 and not np.any(self.t):
            return it.d, np.zeros((n, 3)), np.zeros(n, bool)
        refl = rng.random(n) < self.p_reflect
        out = np.where(refl[:, None], mirror_directions(it), it.d)
        factor = np.where(refl[:, None], self.r / max(self.p_reflect, 1e-300),
                          self.t / max(1.0 - self.p_reflect, 1e-300))
        return out, factor, np.ones(n, bool)

    def branches(self, it: Interaction):
        n = len(it)
        return [(mirror_directions(it), np.tile(self.r, (n, 1)), "reflect"),
                (it.d.copy(), np.tile(self.t, (n, 1)), "transmit")]


class LCD(Surface):
    """LCD modulator: a thin transmittance image, undeviated light.

    T(u, v) = transmittance * (1/CR + (1 - 1/CR) * image(u, v)), so a clear cell transmits
    ``transmittance`` and a black cell ``transmittance / contrast_ratio`` (the paper's 300:1 black
    leak, sec. 3). Cells are looked up nearest-neighbour: the cellular structure is kept.
    """

    kind = "lcd"

    def __init__(self, obj):
        super().__init__(obj)
        p = obj.material.params
        self.image = p["image"]
        self.t_open = p["transmittance"]
        self.contrast = p["contrast_ratio"]

    def transmittance(self, uv: np.ndarray) -> np.ndarray:
        """(n, 3) RGB transmittance at texture coordinates ``uv`` (n, 2); OBJ convention v up."""
        h, w = self.image.shape[:2]
        x = np.clip(np.floor(uv[:, 0] * w).astype(np.int64), 0, w - 1)
        y = np.clip(np.floor((1.0 - uv[:, 1]) * h).astype(np.int64), 0, h - 1)
        cell = self.image[y, x]
        return self.t_open * (1.0 / self.contrast + (1.0 - 1.0 / self.contrast) * cell)

    def scatter(self, it, rng, radiance):
        return it.d, self.transmittance(it.uv), np.ones(len(it), bool)

    def branches(self, it):
        return [(it.d.copy(), self.transmittance(it.uv), "transmit")]


class Lambertian(Surface):
    """Lambertian reflector of RGB albedo rho: BRDF rho / pi on the side the light arrives from."""

    kind = "lambertian"
    scattering = True

    def __init__(self, obj):
        super().__init__(obj)
        self.rho = obj.material.params["reflectance"]
        self.tau = np.zeros(3)
        self._setup()

    def _setup(self):
        yr, yt = float(luminance(self.rho)), float(luminance(self.tau))
        self.p_reflect = yr / (yr + yt) if yr + yt > 0 else 1.0

    def scatter(self, it, rng, radiance):
        n = len(it)
        side = _side(it)
        refl = rng.random(n) < self.p_reflect
        normal = it.ng * (side * np.where(refl, 1.0, -1.0))[:, None]
        t, b, nn = frame_from_normal(normal)
        out = to_world(cosine_hemisphere(rng.random((n, 2))), t, b, nn)
        factor = np.where(refl[:, None], self.rho / max(self.p_reflect, 1e-300),
                          self.tau / max(1.0 - self.p_reflect, 1e-300))
        return out, factor, np.ones(n, bool)

    def eval_fcos(self, it: Interaction, out: np.ndarray) -> np.ndarray:
        """BSDF times |cos(out)|, (n, 3), 1/sr."""
        same = dot(out, it.ng) * dot(it.d, it.ng) < 0  # reflected back to the incident side
        cos = np.abs(dot(out, it.ng))
        return np.where(same[:, None], self.rho, self.tau) * (cos / np.pi)[:, None]

    def pdf(self, it: Interaction, out: np.ndarray) -> np.ndarray:
        same = dot(out, it.ng) * dot(it.d, it.ng) < 0
        cos = np.abs(dot(out, it.ng))
        return np.where(same, self.p_reflect, 1.0 - self.p_reflect) * cos / np.pi


class LambertianTransmitter(Lambertian):
    """Diffuse screen: Lambertian transmission tau (and optional reflection rho), both 1/pi lobes."""

    kind = "lambertian_transmitter"

    def __init__(self, obj):
        Surface.__init__(self, obj)
        p = obj.material.params
        self.rho, self.tau = p["reflectance"], p["transmittance"]
        self._setup()


class GaussianDiffuser(Surface):
    """Transmissive diffuser with a Gaussian lobe around the undeviated direction, in direction-cosine
    space (the narrow-angle "raster scatterer" of the paper's lighting optics, sec. 4.2; the ABg
    family of Harvey, see Stover, doi:10.1117/3.975276). Widths sigma_x, sigma_y follow the object's
    local x axis and its perpendicular; scatter beyond grazing (|beta| >= 1) is absorbed.
    """

    kind = "diffuser"
    scattering = True

    def __init__(self, obj):
        super().__init__(obj)
        p = obj.material.params
        self.tau = p["transmittance"]
        self.sigma = p["sigma"]
        self.axis = obj.local_x

    def _frame(self, it: Interaction):
        if it.frame is None:
            it.frame = frame_from_normal(scale(it.ng, -_side(it)), self.axis)
        return it.frame

    def scatter(self, it, rng, radiance):
        t, b, n = self._frame(it)
        dl = to_local(it.d, t, b, n)
        local, valid = gaussian_lobe(rng.random((len(it), 2)), dl[:, :2], self.sigma)
        out = to_world(local, t, b, n)
        return out, np.where(valid[:, None], self.tau, 0.0), valid

    def pdf(self, it: Interaction, out: np.ndarray) -> np.ndarray:
        t, b, n = self._frame(it)
        return gaussian_lobe_pdf(to_local(out, t, b, n), to_local(it.d, t, b, n)[:, :2], self.sigma)

    def eval_fcos(self, it: Interaction, out: np.ndarray) -> np.ndarray:
        return self.tau * self.pdf(it, out)[:, None]


class Emitter(Absorber):
    """Lambertian area emitter (an LED die, a backlight): luminance L on its front side (both
    sides if two-sided), black to incoming light."""

    kind = "emitter"
    emits = True

    def __init__(self, obj):
        super().__init__(obj)
        p = obj.material.params
        self.luminance = emitter_luminance(obj)
        self.radiance_rgb = self.luminance * p["color"]
        self.two_sided = p["two_sided"]

    def emitted(self, it: Interaction) -> np.ndarray:
        """(n, 3) RGB luminance (cd/m^2) leaving toward the ray's origin."""
        front = dot(it.d, it.ng) < 0
        visible = front | self.two_sided
        return np.where(visible[:, None], self.radiance_rgb, 0.0)


SURFACES: dict[str, type[Surface]] = {
    "absorber": Absorber,
    "mirror": Mirror,
    "dielectric": Dielectric,
    "coating": Coating,
    "lcd": LCD,
    "lambertian": Lambertian,
    "lambertian_transmitter": LambertianTransmitter,
    "diffuser": GaussianDiffuser,
    "emitter": Emitter,
}


def make_surface(obj: SceneObject) -> Surface:
    """The surface implementation of an object's material (found by the material's type name)."""
    return SURFACES[obj.material.type](obj)
