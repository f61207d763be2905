"""The materials: one class each, carrying its schema (the fields of scene.json's "material" block).

Adding a material: write a class here that derives from :class:`tracer.optics.bsdf.BSDF`, give it a
``schema`` (tracer.schema) and the interface methods, and decorate it with :func:`material`. The
loader's validation, the Blender add-on's properties, panel and export, the preset builder and the
Mitsuba converter's check all follow from the schema; tests/test_materials.py runs the chi-square
adapter on every non-delta material and the energy and reciprocity checks on all of them.

Every routine works on a whole batch; the unit tests check energy conservation (and reciprocity
where it applies) against closed forms.
"""

from __future__ import annotations

import numpy as np

from ..sampling import cosine_hemisphere, frame_from_normal, gaussian_lobe, gaussian_lobe_pdf, to_local, to_world
from ..schema import REQUIRED, Field, Schema
from ..units import luminance3
from ..vec import F32, dot, reflect
from .bsdf import BSDF, DELTA, RADIANCE, REFLECTION, TRANSMISSION, BSDFSample, Interaction
from .fresnel import fresnel_unpolarized, refract

#: The smallest positive value the float32 densities and probabilities are clamped to (1e-300 does
#: not exist in float32).
TINY = F32(1e-30)

#: Largest refractive index (germanium, the highest of optical materials, is about 4).
MAX_IOR = 10.0

#: The materials by scene.json type name.
MATERIALS: dict[str, type[BSDF]] = {}


def material(cls: type[BSDF]) -> type[BSDF]:
    """Class decorator: register a material under its schema's name."""
    MATERIALS[cls.schema.name] = cls
    return cls


def _rgb(name: str, default=None, label: str = "", description: str = "", required: bool = True) -> Field:
    """An RGB ratio in [0, 1] (reflectance, transmittance); user interfaces start from 0.9."""
    return Field(name, "rgb", REQUIRED if required else default, unit="1", minimum=0.0, maximum=1.0, label=label,
                 description=description, ui_default=0.9)


def _energy_check(params: dict, fail):
    if np.any(params["reflectance"] + params["transmittance"] > 1 + 1e-12):
        fail("", "reflectance + transmittance must not exceed 1 (energy conservation)")


def _absorbed(n: int) -> BSDFSample:
    return BSDFSample(np.zeros((3, n), F32), np.zeros((1, n), F32), np.zeros(n, F32), np.zeros(n, np.int8))


def mirror_directions(it: Interaction) -> np.ndarray:
    """Specular reflection about the shading normal; where an interpolated normal would send the
    ray through the mesh, about the geometric normal instead. (3, n)."""
    out = reflect(it.d, it.ns)
    if it.ns is it.ng:
        return out  # flat: the reflection is on the incident side by construction
    wrong = dot(out, it.ng) * dot(it.d, it.ng) > 0
    if np.any(wrong):
        out = np.where(wrong, reflect(it.d, it.ng), out)
    return out


@material
class Absorber(BSDF):
    """Black: every ray ends here."""

    schema = Schema("absorber", "Absorber", "Black: absorbs every ray (housings, frames, baffles)")

    def sample(self, it, u, mode):
        return _absorbed(len(it))


@material
class Aperture(BSDF):
    """A virtual surface that is not traced: it names where an optical system's pupil is, for the
    paper's directed sampling (sec. 2) and the backward method's eq. (3) strata."""

    schema = Schema("aperture", "Aperture (virtual, not traced)",
                    "A planar window that is not traced: a target for aiming and for the exit-pupil strata")
    traced = False


@material
class Mirror(BSDF):
    """Ideal mirror of RGB reflectance R, reflecting on both sides about the shading normal."""

    schema = Schema("mirror", "Mirror", "Ideal specular reflector on both sides",
                    (_rgb("reflectance", label="Reflectance", description="Specular reflectance, 0..1 per channel"),))
    flags = DELTA | REFLECTION

    def __init__(self, objects):
        super().__init__(objects)
        self.r = self.table("reflectance")

    def sample(self, it, u, mode):
        n = len(it)
        return BSDFSample(mirror_directions(it), self.gather(self.r, it), np.zeros(n, F32),
                          np.full(n, self.flags, np.int8))

    def lobes(self, it, mode):
        return [(mirror_directions(it), self.gather(self.r, it), self.flags, "reflect")]


@material
class Dielectric(BSDF):
    """Smooth interface between ``ior_outside`` (front, normal side) and ``ior`` (back side).

    Reflection or refraction is chosen with the Fresnel probability (Born & Wolf; see
    :mod:`tracer.optics.fresnel`), so the weight is 1 in flux mode and (n_i / n_t)^2 after refraction
    in radiance mode; total internal reflection reflects. Closed meshes with outward normals.
    """

    schema = Schema("dielectric", "Dielectric (glass)", "Smooth glass surface: Fresnel reflection and refraction",
                    (Field("ior", "number", unit="1", minimum=1.0, maximum=MAX_IOR, label="IOR",
                           description="Refractive index inside the mesh (behind its normals)", ui_default=1.52),
                     Field("ior_outside", "number", 1.0, unit="1", minimum=1.0, maximum=MAX_IOR, label="IOR outside",
                           description="Refractive index on the normals' side")))
    flags = DELTA | REFLECTION | TRANSMISSION
    dims = 1

    def __init__(self, objects):
        super().__init__(objects)
        self.n_in = self.table("ior")
        self.n_out = self.table("ior_outside")

    def _geometry(self, it: Interaction):
        if "fresnel" not in it.cache:
            side = it.side()
            n_face = it.ns * side  # the shading normal on the incident side
            n_in, n_out = self.gather(self.n_in, it), self.gather(self.n_out, it)
            front = side > 0
            n_i = np.where(front, n_out, n_in)
            n_t = np.where(front, n_in, n_out)
            cos_i = np.clip(-dot(it.d, n_face), 0.0, 1.0)
            eta = n_t / n_i
            r, cos_t = fresnel_unpolarized(cos_i, eta)
            it.cache["fresnel"] = (side, n_face, eta, cos_i, r, cos_t)
        return it.cache["fresnel"]

    def _branches(self, it) -> tuple[np.ndarray, np.ndarray]:
        """(reflected, refracted) directions of every ray, computed once per interaction; on smooth
        objects, a branch that the shading normal would send to the wrong side of the geometric one
        is replaced (reflection about the geometric normal, or the straight continuation)."""
        if "branches" not in it.cache:
            side, n_face, eta, cos_i, r, cos_t = self._geometry(it)
            refl = reflect(it.d, n_face)
            refr = refract(it.d, n_face, eta, cos_i, cos_t)
            if it.ns is not it.ng:
                bad = np.sign(dot(refl, it.ng)) != side  # side: the incident side, +1 (front) or -1
                if np.any(bad):
                    refl = np.where(bad, reflect(it.d, it.ng), refl)
                bad = np.sign(dot(refr, it.ng)) != -side
                if np.any(bad):
                    refr = np.where(bad, it.d, refr)
            it.cache["branches"] = (refl, refr)
        return it.cache["branches"]

    def sample(self, it, u, mode):
        side, n_face, eta, cos_i, r, cos_t = self._geometry(it)
        refl = u[0] < r
        w = F32(1) if mode != RADIANCE else np.where(refl, F32(1), 1 / (eta * eta))
        flags = np.where(refl, DELTA | REFLECTION, DELTA | TRANSMISSION).astype(np.int8)
        d_r, d_t = self._branches(it)
        return BSDFSample(np.where(refl, d_r, d_t), np.broadcast_to(w, (1, len(it))), np.zeros(len(it), F32), flags)

    def lobes(self, it, mode):
        side, n_face, eta, cos_i, r, cos_t = self._geometry(it)
        t = 1 - r if mode != RADIANCE else (1 - r) / (eta * eta)
        d_r, d_t = self._branches(it)
        return [(d_r, r[None], DELTA | REFLECTION, "reflect"), (d_t, t[None], DELTA | TRANSMISSION, "refract")]


@material
class Coating(BSDF):
    """Coated thin partial reflector: reflects with R, transmits undeviated with T, absorbs the rest.
    The branch is chosen with probability Y(R) / (Y(R) + Y(T))."""

    schema = Schema("coating", "Coated partial reflector",
                    "Thin coated plate: specular reflectance R, undeviated transmittance T",
                    (_rgb("reflectance", label="Reflectance", description="Specular reflectance, 0..1"),
                     _rgb("transmittance", label="Transmittance", description="Undeviated transmittance, 0..1")),
                    check=_energy_check)
    flags = DELTA | REFLECTION | TRANSMISSION
    dims = 1

    def __init__(self, objects):
        super().__init__(objects)
        self.r, self.t = self.table("reflectance"), self.table("transmittance")
        yr, yt = luminance3(self.r), luminance3(self.t)
        self.p_reflect = np.where(yr + yt > 0, yr / np.where(yr + yt > 0, yr + yt, 1), 0).astype(F32)

    def sample(self, it, u, mode):
        n = len(it)
        p = self.gather(self.p_reflect, it)
        refl = u[0] < p
        out = np.where(refl, mirror_directions(it), it.d)
        r, t = self.gather(self.r, it), self.gather(self.t, it)
        w = np.where(refl, r / np.maximum(p, TINY), t / np.maximum(1 - p, TINY))
        flags = np.where(refl, DELTA | REFLECTION, DELTA | TRANSMISSION).astype(np.int8)
        return BSDFSample(out, w, np.zeros(n, F32), flags)

    def lobes(self, it, mode):
        return [(mirror_directions(it), self.gather(self.r, it), DELTA | REFLECTION, "reflect"),
                (it.d, self.gather(self.t, it), DELTA | TRANSMISSION, "transmit")]


@material
class LCD(BSDF):
    """LCD modulator: a thin transmittance image, undeviated light.

    T(u, v) = transmittance * (1/CR + (1 - 1/CR) * image(u, v)), so a clear cell transmits
    ``transmittance`` and a black cell ``transmittance / contrast_ratio`` (the paper's 300:1 black
    leak, sec. 3). Cells are looked up nearest-neighbour: the cellular structure is kept.
    """

    schema = Schema("lcd", "LCD modulator", "Thin transmissive image (the slide), light passes undeviated",
                    (Field("image", "image", label="Slide", description="Transmittance image: white = clear cell"),
                     Field("image_encoding", "choice", "srgb", choices=("srgb", "linear"), label="Encoding",
                           description="How 8-bit slide values map to transmittance"),
                     _rgb("transmittance", 1.0, "Transmittance", "Transmittance of a clear cell, 0..1",
                          required=False),
                     Field("contrast_ratio", "number", 300.0, unit="1", minimum=1.0, maximum=1e9,
                           label="Contrast ratio", description="Clear-cell over black-cell transmittance")))
    flags = DELTA | TRANSMISSION

    def __init__(self, objects):
        super().__init__(objects)
        #: Per object: (image height, width, (3, H W) cells relative to a clear cell, row-major from the top).
        self.cells = []
        for o in objects:
            p = o.material.params
            img, cr = p["image"], p["contrast_ratio"]
            h, w = img.shape[:2]
            rel = 1.0 / cr + (1.0 - 1.0 / cr) * img.reshape(h * w, 3).T
            t_open = p["transmittance"].reshape(3, 1).astype(F32)
            self.cells.append((h, w, np.ascontiguousarray(rel, dtype=F32), t_open))

    def _lookup(self, it: Interaction, absolute: bool) -> np.ndarray:
        """(3, n) cell values at the rays' texture coordinates (OBJ convention: v up), relative to a
        clear cell or (``absolute``) times the clear cell's transmittance."""
        key = "lcd_abs" if absolute else "lcd_rel"
        if key in it.cache:
            return it.cache[key]
        out = None
        for i, (h, w, rel, t_open) in enumerate(self.cells):
            sel = slice(None) if len(self.cells) == 1 else np.flatnonzero(self.local[it.slot] == i)
            uv = it.uv[:, sel]
            x = np.clip((uv[0] * w).astype(np.int64), 0, w - 1)  # uv >= 0: truncation is floor
            y = np.clip(((1 - uv[1]) * h).astype(np.int64), 0, h - 1)
            cell = np.take(rel, y * w + x, axis=1)
            if absolute:
                cell = cell * t_open
            if len(self.cells) == 1:
                out = cell
            else:
                out = np.empty((3, len(it)), F32) if out is None else out
                out[:, sel] = cell
        it.cache[key] = out
        return out

    def modulation(self, it: Interaction) -> np.ndarray:
        """(3, n) transmittance relative to a clear cell, in [1/CR, 1]."""
        return self._lookup(it, False)

    def transmittance(self, it: Interaction) -> np.ndarray:
        """(3, n) RGB transmittance at the rays' texture coordinates (OBJ convention: v up)."""
        return self._lookup(it, True)

    def sample(self, it, u, mode):
        n = len(it)
        return BSDFSample(it.d, self.transmittance(it), np.zeros(n, F32), np.full(n, self.flags, np.int8))

    def lobes(self, it, mode):
        return [(it.d, self.transmittance(it), self.flags, "transmit")]


@material
class Lambertian(BSDF):
    """Lambertian reflector of RGB albedo rho: BRDF rho / pi on the side the light arrives from
    (about the geometric normal)."""

    schema = Schema("lambertian", "Lambertian reflector", "Matte surface: reflects rho/pi on the side light arrives",
                    (_rgb("reflectance", label="Reflectance", description="Diffuse albedo, 0..1"),), can_aim=True)
    flags = REFLECTION
    dims = 3

    def __init__(self, objects):
        super().__init__(objects)
        self.rho = self.table("reflectance")
        self.tau = np.zeros_like(self.rho)
        self._setup()

    def _setup(self):
        yr, yt = luminance3(self.rho), luminance3(self.tau)
        self.p_reflect = np.where(yr + yt > 0, yr / np.where(yr + yt > 0, yr + yt, 1), 1).astype(F32)

    def sample(self, it, u, mode):
        p = self.gather(self.p_reflect, it)
        refl = u[0] < p
        normal = it.ng * (it.side() * np.where(refl, F32(1), F32(-1)))
        t, b, nn = frame_from_normal(normal)
        wo = to_world(cosine_hemisphere(u[1:3]), t, b, nn)
        cos = dot(wo, nn)
        pdf = np.where(refl, p, 1 - p) * np.maximum(cos, 0) * (1 / np.pi)
        w = np.where(refl, self.gather(self.rho, it) / np.maximum(p, TINY),
                     self.gather(self.tau, it) / np.maximum(1 - p, TINY))
        ok = pdf > 0
        flags = np.where(ok, np.where(refl, REFLECTION, TRANSMISSION), 0).astype(np.int8)
        return BSDFSample(wo, np.where(ok, w, 0), pdf, flags)

    def _same_side(self, it, wo):
        return dot(wo, it.ng) * dot(it.d, it.ng) < 0  # leaves back toward the incident side

    def eval(self, it, wo, mode):
        same = self._same_side(it, wo)
        cos = np.abs(dot(wo, it.ng)) * (1 / np.pi)
        return np.where(same, self.gather(self.rho, it), self.gather(self.tau, it)) * cos

    def pdf(self, it, wo):
        p = self.gather(self.p_reflect, it)
        same = self._same_side(it, wo)
        return np.where(same, p, 1 - p) * np.abs(dot(wo, it.ng)) * (1 / np.pi)


@material
class LambertianTransmitter(Lambertian):
    """Diffuse screen: Lambertian transmission tau (and optional reflection rho), both 1/pi lobes."""

    schema = Schema("lambertian_transmitter", "Diffuse screen (Lambertian transmitter)",
                    "Rear-projection screen: transmits tau/pi and reflects rho/pi",
                    (_rgb("transmittance", label="Transmittance", description="Diffuse transmittance, 0..1"),
                     _rgb("reflectance", 0.0, "Reflectance", "Diffuse reflectance, 0..1", required=False)),
                    can_aim=True, check=_energy_check)
    flags = REFLECTION | TRANSMISSION

    def __init__(self, objects):
        BSDF.__init__(self, objects)
        self.rho, self.tau = self.table("reflectance"), self.table("transmittance")
        self._setup()


@material
class GaussianDiffuser(BSDF):
    """Transmissive diffuser with a Gaussian lobe around the undeviated direction, in direction-cosine
    space (the narrow-angle "raster scatterer" of the paper's lighting optics, sec. 4.2; the ABg
    family of Harvey, see Stover, doi:10.1117/3.975276). Widths sigma_x, sigma_y follow the object's
    local x axis and its perpendicular; scatter beyond grazing (|beta| >= 1) is absorbed. The lobe is
    reciprocal (the Gaussian is even), so both transport modes share it.
    """

    schema = Schema("diffuser", "Gaussian diffuser", "Narrow-angle transmissive scatterer (Gaussian lobe)",
                    (_rgb("transmittance", label="Transmittance", description="Scattered transmittance, 0..1"),
                     Field("sigma_deg", "pair", unit="deg", minimum=0.0, maximum=60.0, exclusive_min=True,
                           label="Lobe width", description="Lobe standard deviations along local x and y, degrees",
                           ui_default=[3.0, 3.0])),
                    can_aim=True)
    flags = TRANSMISSION
    dims = 2

    def __init__(self, objects):
        super().__init__(objects)
        self.tau = self.table("transmittance")
        self.sigma = np.sin(np.radians(self.table("sigma_deg")))  # (2, objects), direction cosines
        self.axis = np.stack([o.local_x for o in objects], axis=-1).astype(F32)  # (3, objects)

    def _frame(self, it: Interaction):
        if "frame" not in it.cache:
            it.cache["frame"] = frame_from_normal(it.ng * -it.side(), self.gather(self.axis, it))
        return it.cache["frame"]

    def _beta0(self, it: Interaction) -> np.ndarray:
        if "beta0" not in it.cache:
            t, b, n = self._frame(it)
            it.cache["beta0"] = np.stack([dot(it.d, t), dot(it.d, b)])
        return it.cache["beta0"]

    def sample(self, it, u, mode):
        t, b, n = self._frame(it)
        sigma = self.gather(self.sigma, it)
        local, valid = gaussian_lobe(u, self._beta0(it), sigma)
        pdf = np.where(valid, gaussian_lobe_pdf(local, self._beta0(it), sigma), 0)
        flags = np.where(valid, TRANSMISSION, 0).astype(np.int8)
        return BSDFSample(to_world(local, t, b, n), np.where(valid, self.gather(self.tau, it), 0), pdf, flags)

    def pdf(self, it, wo):
        t, b, n = self._frame(it)
        return gaussian_lobe_pdf(to_local(wo, t, b, n), self._beta0(it), self.gather(self.sigma, it))

    def eval(self, it, wo, mode):
        return self.gather(self.tau, it) * self.pdf(it, wo)

    def eval_pdf(self, it, wo, mode):
        pdf = self.pdf(it, wo)
        return self.gather(self.tau, it) * pdf, pdf

    def prepare(self, it):
        self._beta0(it)


def make_materials(objects: list) -> list[BSDF]:
    """One material instance per type present among ``objects`` (scene objects with ``slot``), in the
    order of :data:`MATERIALS`."""
    out = []
    for name, cls in MATERIALS.items():
        objs = [o for o in objects if o.material.type == name]
        if objs:
            out.append(cls(objs))
    return out
