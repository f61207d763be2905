"""The materials: one class each, carrying its schema (the fields of scene.json's "material" block).

Adding a material: write a class here that derives from :class:`tracer.optics.bsdf.BSDF`, give it a
``schema`` (tracer.core.schema) and the interface methods, and decorate it with :func:`material`. The
loader's validation, the Blender add-on's properties, panel and export, the preset builder and the
Mitsuba converter's check all follow from the schema; tests/optics/test_materials.py runs the chi-square
adapter on every non-delta material and the energy and reciprocity checks on all of them.

Every routine works on a whole batch; the unit tests check energy conservation (and reciprocity
where it applies) against closed forms.
"""

from __future__ import annotations

import numpy as np

from ..core.sampling import cosine_hemisphere, frame_from_normal, gaussian_lobe, gaussian_lobe_pdf, to_local, to_world
from ..core.schema import REQUIRED, Field, Schema
from ..core.units import luminance3
from ..core.vec import F32, dot, reflect, take
from .bsdf import BSDF, DELTA, RADIANCE, REFLECTION, TRANSMISSION, BSDFSample, Interaction
from .fresnel import fresnel_amplitudes, refract, unpolarized_from_amplitudes
from .polar import POLARISE, SP, Mueller, amplitudes, axis_frame, s_frame, sp_from_amplitudes, sp_from_powers, state_s1

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


def _rgb(name: str, default=None, label: str = "", description: str = "", required: bool = True,
         ui_default: float = 0.9) -> Field:
    """An RGB ratio in [0, 1] (reflectance, transmittance); user interfaces start from ``ui_default``."""
    return Field(name, "rgb", REQUIRED if required else default, unit="1", minimum=0.0, maximum=1.0, label=label,
                 description=description, ui_default=ui_default)


def _energy_check(params: dict, fail):
    if np.any(params["reflectance"] + params["transmittance"] > 1 + 1e-12):
        fail("", "reflectance + transmittance must not exceed 1 (energy conservation)")


#: Whether a material with two delta branches chooses between them by the arriving path's state of
#: polarisation (:func:`polarised_share`) rather than by the unpolarised weights (a switch for tests
#: and benchmarks; the estimate is unbiased either way).
POLARISED_CHOICE = True


def polarised_share(it: Interaction, mode: str, x: np.ndarray, p, w_a, w_b, b_a, b_b) -> np.ndarray:
    """The probability (n,) of the first of two delta branches for paths in the state ``it.polar``: the
    defensive mixture (Hesterberg 1995, doi:10.1080/00401706.1995.10484303) of the material's
    unpolarised probability ``p`` and the path's own share a_a / (a_a + a_b), a = w (1 + b s1), with w a
    branch's unpolarised weight ((n,), or (3, n) RGB taken by luminance), b its diattenuation (the
    first element of its normalised Mueller row, tracer.optics.polar) and s1 the path's S1 / S0 in the
    branches' s/p frame ``x``.

    The own share is the branch's part of the flux of the path's state (R_s for s light): chosen by
    the unpolarised R alone, a chain of k reflections of s light at a windshield (R_s = 0.26 against
    R = 0.14 at 67 deg) is met (R / R_s)^k times as often as it carries light, each time with a weight
    (R_s / R)^k, so that ghosts of the third and higher orders come in rare, heavy samples. The own
    share alone would in turn sample p light's reflection (R_p = 0.02) 7 times as rarely as today,
    where the reflection is what reaches the eye; the even mixture keeps every branch's second moment
    within twice that of the better of the two rules."""
    k = it.d if mode != RADIANCE else -it.d  # camera paths' frames are those of the light toward the eye
    s1 = state_s1(it.polar, x, k)

    def carried(w, b):
        a = w * np.maximum(1 + b * s1, 0)
        return luminance3(a) if a.shape[0] == 3 else a.mean(axis=0)

    a, b = carried(w_a, b_a), carried(w_b, b_b)
    total = a + b
    own = np.where(total > 0, a / np.where(total > 0, total, 1), p)
    return (0.5 * (p + own)).astype(F32)


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


def _axis_deg(description: str, default=REQUIRED) -> Field:
    return Field("axis_deg", "number", default, unit="deg", minimum=-360.0, maximum=360.0, label="Axis",
                 description=description, ui_default=0.0)


def _reflection_frame(it: Interaction) -> np.ndarray:
    """The s direction of every ray's plane of incidence on the shading normal, (3, n)."""
    if "s_frame" not in it.cache:
        it.cache["s_frame"] = s_frame(it.d, it.ns)
    return it.cache["s_frame"]


#: The Mueller matrix of a reflection that keeps the light's polarisation (an ideal mirror's r_s = -1,
#: r_p = 1 in the s/p frames of tracer.optics.polar): the flip of the p basis on reflection.
IDEAL_REFLECTION = {"b": 0.0, "c": -1.0, "d": 0.0}


def _metal_check(params: dict, fail):
    """A metal's complex index must reflect at normal incidence: R(0) = |(1 - eta) / (1 + eta)|^2, which
    the angular law divides by (n = 1, kappa = 0 reflects nothing; a real metal's R(0) is above 0.5)."""
    metal = params.get("metal")
    if metal is not None:
        eta = complex(*metal["complex_ior"])
        r0 = abs((1 - eta) / (1 + eta)) ** 2 if eta != -1 else 1.0
        if eta.real <= 0:
            fail("metal.complex_ior", f"n must be above 0, got {eta.real:g} (aluminium at 550 nm: 0.96, 6.69)")
        if r0 < 1e-3:
            fail("metal.complex_ior", f"n = {eta.real:g}, kappa = {eta.imag:g} reflects {r0:.3g} at normal incidence, "
                                      "below 0.001: not a metal (aluminium at 550 nm: 0.96, 6.69)")


@material
class Mirror(BSDF):
    """Mirror of RGB reflectance R, reflecting on both sides about the shading normal.

    Ideal by default (every polarisation reflected alike, R at every angle). With a ``metal`` block, the
    complex refractive index n + i kappa of a metal (Born & Wolf sec. 14.2) gives the s and p
    amplitudes: R(theta) = R (R_s + R_p) / 2 / R_metal(0), so that ``reflectance`` stays the measured
    normal-incidence value, and the reflection polarises (tracer.optics.polar).
    """

    schema = Schema("mirror", "Mirror", "Specular reflector on both sides",
                    (_rgb("reflectance", label="Reflectance",
                          description="Specular reflectance (at normal incidence for a metal), 0..1 per channel"),
                     Field("metal", "group", None, label="Metal",
                           description="Fresnel reflection of a metal: angle-dependent and polarising",
                           fields=(Field("complex_ior", "pair", unit="1", minimum=0.0, maximum=100.0,
                                         label="Complex IOR", description="n and kappa of the metal (aluminium "
                                         "at 550 nm: 0.96, 6.69)", ui_default=[0.96, 6.69]),))),
                    check=_metal_check)
    flags = DELTA | REFLECTION

    def __init__(self, objects):
        super().__init__(objects)
        self.r = self.table("reflectance")
        metal = [o.material.params.get("metal") for o in objects]
        self.metal = any(m is not None for m in metal)
        self.polarising = self.metal
        if self.metal:
            # eta per object (complex); ideal mirrors among them: eta = infinity is approximated by a
            # flag (r_s = -1, r_p = 1 exactly).
            self.eta = np.array([complex(*m["complex_ior"]) if m is not None else 0j for m in metal])
            self.is_metal = np.array([m is not None for m in metal])
            rs, rp, _, _ = amplitudes(np.ones(len(metal)), np.where(self.is_metal, self.eta, 1.0))
            self.r_normal = np.where(self.is_metal, 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2), 1.0)

    def _metal(self, it: Interaction):
        """(weight factor R(theta) / R(0) (n,), (b, c, d)) of the rays' objects, cached."""
        if "metal" not in it.cache:
            local = self.local[it.slot]
            cos_i = np.abs(dot(it.d, it.ns))
            eta = self.eta[local]
            metal = self.is_metal[local]
            rs, rp, _, _ = amplitudes(cos_i, np.where(metal, eta, 1.0))
            factor = np.where(metal, 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2) / self.r_normal[local], 1.0)
            b, c, d = sp_from_amplitudes(rs, rp)
            it.cache["metal"] = (factor.astype(F32), np.where(metal, b, F32(0)), np.where(metal, c, F32(-1)),
                                 np.where(metal, d, F32(0)))
        return it.cache["metal"]

    def _weight(self, it):
        r = self.gather(self.r, it)
        return r * self._metal(it)[0] if self.metal else r

    def sample(self, it, u, mode):
        n = len(it)
        return BSDFSample(mirror_directions(it), self._weight(it), np.zeros(n, F32), np.full(n, self.flags, np.int8))

    def lobes(self, it, mode):
        return [(mirror_directions(it), self._weight(it), self.flags, "reflect")]

    def mueller(self, it, k_in, k_out, flags):
        x = _reflection_frame(it)
        if not self.metal:
            return Mueller(SP, x, x, **IDEAL_REFLECTION)
        _, b, c, d = self._metal(it)
        return Mueller(SP, x, x, b, c, d)


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
    polarising = True

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
            rs, rp, cos_t, tir = fresnel_amplitudes(cos_i, eta)
            r, cos_t = unpolarized_from_amplitudes(rs, rp, cos_t, tir)
            it.cache["fresnel"] = (side, n_face, eta, cos_i, r, cos_t)
            it.cache["fresnel_amplitudes"] = (rs, rp)
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
        """Reflection with probability R (unpolarised paths) or with the path's own share of it
        (:func:`polarised_share`); the weight is the branch's R or T over that probability."""
        side, n_face, eta, cos_i, r, cos_t = self._geometry(it)
        if it.polar is None or not POLARISED_CHOICE:
            refl = u[0] < r
            w = F32(1) if mode != RADIANCE else np.where(refl, F32(1), 1 / (eta * eta))
        else:
            x, refl_sp, refr_sp = self._sp(it)
            q = polarised_share(it, mode, x, r, r, 1 - r, refl_sp[0], refr_sp[0])  # 1 at total reflection
            refl = u[0] < q
            t = self._refracted_weight(r, eta, mode)
            w = np.where(refl, r / np.maximum(q, TINY), t / np.maximum(1 - q, TINY)).astype(F32)
        flags = np.where(refl, DELTA | REFLECTION, DELTA | TRANSMISSION).astype(np.int8)
        d_r, d_t = self._branches(it)
        return BSDFSample(np.where(refl, d_r, d_t), np.broadcast_to(w, (1, len(it))), np.zeros(len(it), F32), flags)

    @staticmethod
    def _refracted_weight(r, eta, mode):
        """The refracted branch's weight T = 1 - R, times (n_i / n_t)^2 for radiance (camera paths)."""
        return 1 - r if mode != RADIANCE else (1 - r) / (eta * eta)

    def lobes(self, it, mode):
        side, n_face, eta, cos_i, r, cos_t = self._geometry(it)
        t = self._refracted_weight(r, eta, mode)
        d_r, d_t = self._branches(it)
        return [(d_r, r[None], DELTA | REFLECTION, "reflect"), (d_t, t[None], DELTA | TRANSMISSION, "refract")]

    def mueller(self, it, k_in, k_out, flags):
        """Fresnel reflection or refraction in the s/p frame of the plane of incidence (Born & Wolf sec.
        1.5.2; total internal reflection with its phase, sec. 1.5.4). Reflection and refraction are
        reciprocal, so camera paths and light paths share the matrices."""
        x, refl, refr = self._sp(it)
        is_r = (flags & REFLECTION) != 0
        b, c, d = (np.where(is_r, a, t) for a, t in zip(refl, refr, strict=True))
        return Mueller(SP, x, x, b, c, d)

    def _sp(self, it: Interaction):
        """(s frame (3, n), reflection's (b, c, d), refraction's (b, c, d)), computed once per interaction."""
        if "fresnel_sp" not in it.cache:
            side, n_face, eta, cos_i, r, cos_t = self._geometry(it)
            rs, rp = it.cache["fresnel_amplitudes"]  # real; total internal reflection's phase below
            refl, refr = sp_from_amplitudes(rs, rp), sp_from_amplitudes(1 + rs, (1 + rp) / eta)
            tir = np.flatnonzero(r >= 1)
            if len(tir):
                a_s, a_p, _, _ = amplitudes(cos_i[tir], np.broadcast_to(eta, cos_i.shape)[tir])
                for out, v in zip(refl, sp_from_amplitudes(a_s, a_p), strict=True):
                    out[tir] = v
            it.cache["fresnel_sp"] = (s_frame(it.d, n_face), refl, refr)
        return it.cache["fresnel_sp"]


def _coating_check(params: dict, fail):
    if "reflectance_s" in params:
        for pol in "sp":
            if np.any(params[f"reflectance_{pol}"] + params[f"transmittance_{pol}"] > 1 + 1e-12):
                fail("", f"reflectance_{pol} + transmittance_{pol} must not exceed 1 (energy conservation)")
    else:
        _energy_check(params, fail)


@material
class Coating(BSDF):
    """Coated thin partial reflector: reflects with R, transmits undeviated with T, absorbs the rest.
    The branch is chosen with probability Y(R) / (Y(R) + Y(T)) (with s/p values, by the path's own
    share of them: :func:`polarised_share`).

    Given R_s, R_p, T_s, T_p (the coating's reflectances and transmittances for s and p light at its
    angle of use) instead of R and T, it polarises: R = (R_s + R_p) / 2 and T = (T_s + T_p) / 2 for
    unpolarised light, and the Mueller matrices of a diattenuator in the s/p frame of each ray's plane
    of incidence, without retardance (tracer.optics.polar).
    """

    schema = Schema("coating", "Coated partial reflector",
                    "Thin coated plate: specular reflectance R, undeviated transmittance T",
                    # a user interface starts from a combiner's coating, lossy and s-reflecting: R + T <= 1
                    (_rgb("reflectance", label="Reflectance", description="Specular reflectance, 0..1", required=False,
                          ui_default=0.25),
                     _rgb("transmittance", label="Transmittance", description="Undeviated transmittance, 0..1",
                          required=False, ui_default=0.7),
                     _rgb("reflectance_s", label="Reflectance s", description="Reflectance for s light, 0..1",
                          required=False, ui_default=0.35),
                     _rgb("reflectance_p", label="Reflectance p", description="Reflectance for p light, 0..1",
                          required=False, ui_default=0.15),
                     _rgb("transmittance_s", label="Transmittance s", description="Transmittance for s light, 0..1",
                          required=False, ui_default=0.6),
                     _rgb("transmittance_p", label="Transmittance p", description="Transmittance for p light, 0..1",
                          required=False, ui_default=0.8)),
                    alternatives=(("reflectance", "transmittance"),
                                  ("reflectance_s", "reflectance_p", "transmittance_s", "transmittance_p")),
                    check=_coating_check)
    flags = DELTA | REFLECTION | TRANSMISSION
    dims = 1

    def __init__(self, objects):
        super().__init__(objects)
        params = [o.material.params for o in objects]
        self.polarising = any("reflectance_s" in p for p in params)
        rgb = lambda p, k: np.asarray(p[k], dtype=F32)  # noqa: E731
        if self.polarising:
            # Every object as s/p values (an unpolarised one: R_s = R_p = R).
            names = ("reflectance_s", "reflectance_p", "transmittance_s", "transmittance_p")
            sp = [tuple(rgb(p, k) for k in names) if "reflectance_s" in p
                  else (rgb(p, "reflectance"),) * 2 + (rgb(p, "transmittance"),) * 2 for p in params]
            rs, rp, ts, tp = (np.stack([v[i] for v in sp], axis=-1) for i in range(4))
            self.r, self.t = 0.5 * (rs + rp), 0.5 * (ts + tp)
            self.sp_reflect = sp_from_powers(rs, rp, sign=-1.0)  # each (3, objects)
            self.sp_transmit = sp_from_powers(ts, tp)
            #: The matrices differ by channel: paths need a polarisation state per channel.
            self.chromatic_polarisation = any(float(np.ptp(a, axis=0).max()) > 1e-7
                                              for a in (*self.sp_reflect, *self.sp_transmit))
            if not self.chromatic_polarisation:  # one row, as the paths then carry one state for all channels
                self.sp_reflect = tuple(a[:1] for a in self.sp_reflect)
                self.sp_transmit = tuple(a[:1] for a in self.sp_transmit)
        else:
            self.r, self.t = self.table("reflectance"), self.table("transmittance")
        yr, yt = luminance3(self.r), luminance3(self.t)
        self.p_reflect = np.where(yr + yt > 0, yr / np.where(yr + yt > 0, yr + yt, 1), 0).astype(F32)

    def sample(self, it, u, mode):
        n = len(it)
        r, t = self.gather(self.r, it), self.gather(self.t, it)
        p = self.gather(self.p_reflect, it)
        if self.polarising and it.polar is not None and POLARISED_CHOICE:
            p = polarised_share(it, mode, _reflection_frame(it), p, r, t, self.gather(self.sp_reflect[0], it),
                                self.gather(self.sp_transmit[0], it))
        refl = u[0] < p
        out = np.where(refl, mirror_directions(it), it.d)
        w = np.where(refl, r / np.maximum(p, TINY), t / np.maximum(1 - p, TINY))
        flags = np.where(refl, DELTA | REFLECTION, DELTA | TRANSMISSION).astype(np.int8)
        return BSDFSample(out, w, np.zeros(n, F32), flags)

    def lobes(self, it, mode):
        return [(mirror_directions(it), self.gather(self.r, it), DELTA | REFLECTION, "reflect"),
                (it.d, self.gather(self.t, it), DELTA | TRANSMISSION, "transmit")]

    def mueller(self, it, k_in, k_out, flags):
        is_r = (flags & REFLECTION) != 0
        x = _reflection_frame(it)
        if not self.polarising:
            if not np.any(is_r):
                return None
            return Mueller(SP, x, x, F32(0), np.where(is_r, F32(-1), F32(1)), F32(0))
        b, c, d = (np.where(is_r, self.gather(a, it), self.gather(t, it))
                   for a, t in zip(self.sp_reflect, self.sp_transmit, strict=True))
        return Mueller(SP, x, x, b, c, d)


@material
class LCD(BSDF):
    """LCD modulator: a thin transmittance image, undeviated light.

    T(u, v) = transmittance * (1/CR + (1 - 1/CR) * image(u, v)), so a clear cell transmits
    ``transmittance`` and a black cell ``transmittance / contrast_ratio`` (the paper's 300:1 black
    leak, sec. 3). Cells are looked up nearest-neighbour: the cellular structure is kept.

    With a ``polariser`` block the panel's output polariser leaves its light (the symbols' and the black
    leak's alike) linearly polarised along its axis, at ``axis_deg`` from the object's local x axis
    toward its local y axis: Mueller matrix T [[1, 0, 0, 0], [1, 0, 0, 0], 0, 0] in the axis frame
    (the panel's rear polariser, liquid crystal and front polariser as one element fed by an
    unpolarised backlight: T stays the panel's transmittance for unpolarised light).
    """

    schema = Schema("lcd", "LCD modulator", "Thin transmissive image (the slide), light passes undeviated",
                    (Field("image", "image", label="Slide", description="Transmittance image: white = clear cell"),
                     Field("image_encoding", "choice", "srgb", choices=("srgb", "linear"), label="Encoding",
                           description="How 8-bit slide values map to transmittance"),
                     _rgb("transmittance", 1.0, "Transmittance", "Transmittance of a clear cell, 0..1",
                          required=False),
                     Field("contrast_ratio", "number", 300.0, unit="1", minimum=1.0, maximum=1e9,
                           label="Contrast ratio", description="Clear-cell over black-cell transmittance"),
                     Field("polariser", "group", None, label="Output polariser",
                           description="The panel's light leaves linearly polarised along this axis",
                           fields=(_axis_deg("Transmission axis, degrees from the object's local x axis toward "
                                             "its local y axis"),))))
    flags = DELTA | TRANSMISSION

    def __init__(self, objects):
        super().__init__(objects)
        pol = [o.material.params.get("polariser") for o in objects]
        self.polarising = any(p is not None for p in pol)
        if self.polarising:
            self.pol_axis = np.stack([o.axis(p["axis_deg"]) if p is not None else o.local_x
                                      for o, p in zip(objects, pol, strict=True)], axis=-1).astype(F32)
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
            cell = take(rel, y * w + x)
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

    def mueller(self, it, k_in, k_out, flags):
        if not self.polarising:
            return None
        axis = self.gather(self.pol_axis, it)  # every LCD of the scene has one (tracer.scene checks)
        return Mueller(POLARISE, axis_frame(axis, k_in), axis_frame(axis, k_out))


@material
class Retarder(BSDF):
    """Thin retarder film (a half-wave plate by default): transmits T undeviated and delays the light
    polarised across its fast axis by the retardance delta; Mueller matrix T [[1, 0, 0, 0], [0, 1, 0, 0],
    [0, 0, cos delta, sin delta], [0, 0, -sin delta, cos delta]] in the frame of the fast axis (Collett,
    Field Guide to Polarization, doi:10.1117/3.626141). A half-wave film turns linear polarisation at
    angle a to its axis to -a: at 45 degrees, s light becomes p light (HUDs use it for polarised
    sunglasses). Normal incidence is assumed for the retardance."""

    schema = Schema("retarder", "Retarder film (half-wave plate)",
                    "Thin film that rotates linear polarisation (undeviated transmission)",
                    (_rgb("transmittance", 1.0, "Transmittance", "Transmittance, 0..1", required=False),
                     _axis_deg("Fast axis, degrees from the object's local x axis toward its local y axis"),
                     Field("retardance_deg", "number", 180.0, unit="deg", minimum=0.0, maximum=360.0,
                           label="Retardance", description="Phase delay between the axes, degrees (180: half-wave)")))
    flags = DELTA | TRANSMISSION

    def __init__(self, objects):
        super().__init__(objects)
        self.t = self.table("transmittance")
        self.axis = np.stack([o.axis(o.material.params["axis_deg"]) for o in objects], axis=-1).astype(F32)
        delta = np.radians(self.table("retardance_deg"))
        self.cos_d, self.sin_d = np.cos(delta).astype(F32), np.sin(delta).astype(F32)

    def sample(self, it, u, mode):
        n = len(it)
        return BSDFSample(it.d, self.gather(self.t, it), np.zeros(n, F32), np.full(n, self.flags, np.int8))

    def lobes(self, it, mode):
        return [(it.d, self.gather(self.t, it), self.flags, "transmit")]

    def mueller(self, it, k_in, k_out, flags):
        x = axis_frame(self.gather(self.axis, it), k_in)
        return Mueller(SP, x, x, F32(0), self.gather(self.cos_d, it), self.gather(self.sin_d, it))


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
                     Field("sigma_deg", "pair", unit="deg", minimum=1e-3, maximum=60.0,
                           label="Lobe width", description="Lobe standard deviations along local x and y, degrees "
                                                           "(0.001 at least: float32 directions resolve 1e-5 deg)",
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
