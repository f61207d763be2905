"""A tracer scene as a Mitsuba 3 scene: the same geometry (world millimetres), units and physics.

    from benchmarks.mitsuba_scene import VARIANT, load
    mi_scene = load(tracer.scene.load_scene(folder))     # then mi.render(mi_scene, integrator=..., seed=...)

Variant: ``llvm_ad_rgb`` on one Dr.Jit thread when ``DRJIT_LIBLLVM_PATH`` names an existing LLVM
library (Mitsuba's llvm variants crash with Debian's LLVM 14/15, "Cannot select ... fminimum"; LLVM 19
works, and ``make bench`` installs it), otherwise ``scalar_rgb`` (slow with the Python plugins below,
but it needs nothing). The variant is set when this module is imported.

Units: lengths stay in mm (Mitsuba has no unit of its own; its ray offsets are relative to the
coordinates). Emitters and environments are given their luminance in cd/m^2 times the tracer's
colour normalised to Y = 1, so the film's linear Rec.709 RGB has Y = 0.2126 R + 0.7152 G + 0.0722 B
in cd/m^2, as the tracer's (Mitsuba's RGB variants use Rec.709 primaries).

Materials (tracer/optics/surfaces.py against Mitsuba 3.9's plugins):

- ``mirror`` -> ``twosided(conductor(material="none", specular_reflectance=R))``: R at every angle on
  both sides, about the shading normal (ours too; ours falls back to the geometric normal where the
  interpolated one would reflect into the mesh, Mitsuba does not).
- ``dielectric`` -> ``dielectric(int_ior=ior, ext_ior=ior_outside)``: the same unpolarised Fresnel
  equations (Born & Wolf), the same convention (the normal points to the outside medium), the same
  choice of reflection or refraction with probability R, and the same (n_i/n_t)^2 radiance scaling.
- ``lcd`` -> ``thindielectric(int_ior=ext_ior=1, specular_transmittance=T(uv))``: with equal indices the
  Fresnel reflectance is 0, so every ray passes undeviated with weight T(uv), RGB, as the tracer's LCD;
  T(uv) = transmittance (1/CR + (1 - 1/CR) image) is a raw nearest-neighbour bitmap, and the mesh's
  texture coordinates are flipped in v to Mitsuba's bitmap convention (row 0 at v = 0). Checked:
  hud-direct's symbols land on the same pixels as in the tracer's image (the cross-check in
  mitsuba_peer.py). A ``mask`` would let rays through with probability T instead, a noisier estimator.
- ``coating`` -> ``blendbsdf(weight=p_t, conductor(R / (1 - p_t)), thindielectric(eta 1, T / p_t))``
  with p_t = Y(T) / (Y(R) + Y(T)): blendbsdf picks a component with its weight and keeps the
  component's own weight, so this is the tracer's Coating estimator exactly (reflect with probability
  1 - p_t and weight R / (1 - p_t), pass undeviated with p_t and T / p_t). Colours as raw bitmaps,
  which may exceed 1.
- ``lambertian`` -> ``twosided(diffuse)``: rho/pi on the side the light arrives from, as ours.
- ``lambertian_transmitter`` -> :class:`LambertianTransmitter`, a Python BSDF (Mitsuba 3 has no diffuse
  transmitter): rho/pi back to the incident side, tau/pi through, each side chosen with probability
  Y(rho)/(Y(rho)+Y(tau)) and a cosine lobe, as the tracer's LambertianTransmitter.
- ``diffuser`` -> :class:`GaussianDiffuser`, a Python BSDF with the tracer's lobe exactly (direction-
  cosine Gaussian about the undeviated direction, sigma along the object's local x and its
  perpendicular, |beta| >= 1 absorbed); mitsuba_checks.py compares its pdf with
  tracer.core.sampling.gaussian_lobe_pdf and runs Mitsuba's chi-square test on its sampling.
- ``absorber`` -> ``diffuse(reflectance=0)``.
- ``aperture`` -> nothing (not traced).
- an object's emission block -> an ``area`` emitter of radiance L c on the object's own BSDF; the
  luminance from a flux is the tracer's own (tracer.sources.lights.make_emission, at load), so a flux is
  converted exactly as the tracer does. Mitsuba's area lights emit on the front side only: a
  two-sided emitter gets a second, flipped copy of its triangles, and both copies are moved
  apart by 1e-5 (1 + max |x|) mm along their own normals so that each is hit first from its side.

The converter checks itself against the tracer's material schema when it is imported
(:data:`MAPPED_FIELDS`): a material or a field the schema has and this mapping does not read stops
the benchmark, so a new material cannot be compared silently wrong.

Environment: ``none`` -> none, ``uniform`` -> ``constant``, ``hdri`` -> ``envmap`` of the same pixels
with ``scale`` = the tracer's calibration factor k and ``to_world`` = R_z(rotation_deg) times the map of
Mitsuba's y-up panorama (u = atan2(x, -z) / 2 pi) onto Blender's z-up one (u = 0.5 - atan2(y, x) / 2 pi):
local (x, y, z) = world (y, z, x). mitsuba_checks.py puts a bright spot in a synthetic HDRI and finds
it in the same column in both renderers and 0.16 deg higher in Mitsuba at 20 deg elevation on a
128-row map, as expected if Mitsuba's envmap puts row i at latitude 90 - 180 i / (H - 1) deg where
Blender and the tracer put it at 90 - 180 (i + 1/2) / H deg (a fraction of a map row; no remedy).

Sensor: :class:`ThinLensEye`, Mitsuba's thinlens camera (same sampling and weight 1, i.e. the mean
radiance over the pixel's tangent-plane area and the lens area, and its importance for the particle
tracer) with two changes: the pixel grid is the eye's own, whose field angles need not match one
field angle and the aspect ratio of the resolution (Mitsuba's thinlens has square pixels, and
analytic-mirror's 30 x 22.5 deg on 64 x 48 pixels differs by 1 % in height), and an infinite
accommodation distance is exact. mitsuba_checks.py renders it against Mitsuba's thinlens with square
pixels: the same image for the same seed. The tracer weights each (pixel point, pupil point) by
cos^4(theta) / f^2 (tracer/transport/eye.py) instead of 1; the two agree where the luminance is constant over
a pixel's ray bundle, and otherwise differ in second order (cos^4 varies by 4 tan(theta) dtheta
across a pixel).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from tracer.core.imageio import read_image
from tracer.core.units import luminance
from tracer.optics.materials import MATERIALS
from tracer.scene import Scene, SceneObject
from tracer.sources.environment import HdriEnvironment, UniformEnvironment
from tracer.sources.sun import EnvironmentWithSun

_LLVM = os.environ.get("DRJIT_LIBLLVM_PATH", "")
#: The Mitsuba variant in use (see the module docstring).
VARIANT = "llvm_ad_rgb" if _LLVM and Path(_LLVM).is_file() else "scalar_rgb"
mi.set_variant(VARIANT)
dr.set_thread_count(1)

#: Displacement of the two copies of a two-sided emitter, relative to 1 + the largest |coordinate|, mm/mm.
TWO_SIDED_OFFSET = 1e-5

_GLOSSY_T = mi.BSDFFlags.GlossyTransmission | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
_DIFFUSE_RT = (mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.DiffuseTransmission | mi.BSDFFlags.FrontSide
               | mi.BSDFFlags.BackSide)


class GaussianDiffuser(mi.BSDF):
    """The tracer's ``diffuser`` (tracer.optics.surfaces.GaussianDiffuser) as a vectorised Mitsuba BSDF.

    Frame: the normal n is the geometric normal on the side the light leaves to; t is the object's
    local x axis made perpendicular to n (where the axis is parallel to n, Mitsuba's
    coordinate_system: the Duff et al. frame, as in the tracer); b = n x t. With d the propagation direction
    (-wi) and beta the (t, b) components of a direction: f |cos| = tau g2(beta_out - beta_d; sigma)
    (n . out) for n . out > 0, which is tau times the tracer's gaussian_lobe_pdf; sampling draws
    beta_out = beta_d + sigma z (Box-Muller from sample2, as the tracer) and absorbs |beta_out| >= 1.
    The lobe is reciprocal (g2 is even), so radiance and importance transport share it.
    Properties: tau (RGB), sigma_x, sigma_y (direction cosines), axis (world vector).
    """

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        self.tau = mi.Color3f(props["tau"])
        self.sigma_x, self.sigma_y = props["sigma_x"], props["sigma_y"]
        self.axis = mi.Vector3f(props["axis"])
        self.m_components = [_GLOSSY_T]
        self.m_flags = _GLOSSY_T

    def _frame(self, si):
        d = -si.to_world(si.wi)
        n = dr.mulsign(si.n, dr.dot(d, si.n))
        t = self.axis - dr.dot(self.axis, n) * n
        t_len = dr.norm(t)
        t = dr.select(t_len > 1e-6, t / t_len, mi.coordinate_system(n)[0])
        b = dr.cross(n, t)
        return d, t, b, n

    def _pdf(self, si, out):
        d, t, b, n = self._frame(si)
        zx = (dr.dot(out, t) - dr.dot(d, t)) / self.sigma_x
        zy = (dr.dot(out, b) - dr.dot(d, b)) / self.sigma_y
        cos_out = dr.dot(out, n)
        g2 = dr.exp(-0.5 * (zx * zx + zy * zy)) / (2 * dr.pi * self.sigma_x * self.sigma_y)
        return dr.select(cos_out > 0, g2 * cos_out, 0.0)

    def sample(self, ctx, si, sample1, sample2, active=True):
        d, t, b, n = self._frame(si)
        radius = dr.sqrt(-2.0 * dr.log(1.0 - sample2.x))
        sin_a, cos_a = dr.sincos(2.0 * dr.pi * sample2.y)
        zx, zy = radius * cos_a, radius * sin_a
        bx = dr.dot(d, t) + self.sigma_x * zx
        by = dr.dot(d, b) + self.sigma_y * zy
        beta2 = bx * bx + by * by
        valid = active & (beta2 < 1.0)
        cos_out = dr.safe_sqrt(1.0 - beta2)
        out = bx * t + by * b + cos_out * n
        bs = mi.BSDFSample3f()
        bs.wo = si.to_local(out)
        bs.pdf = dr.select(valid, dr.exp(-0.5 * (zx * zx + zy * zy)) / (2 * dr.pi * self.sigma_x * self.sigma_y)
                           * cos_out, 0.0)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyTransmission)
        bs.sampled_component = mi.UInt32(0)
        return bs, dr.select(valid, self.tau, mi.Color3f(0.0))

    def eval(self, ctx, si, wo, active=True):
        return dr.select(active, self.tau * self._pdf(si, si.to_world(wo)), mi.Color3f(0.0))

    def pdf(self, ctx, si, wo, active=True):
        return dr.select(active, self._pdf(si, si.to_world(wo)), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        p = dr.select(active, self._pdf(si, si.to_world(wo)), 0.0)
        return self.tau * p, p

    def to_string(self):
        return f"GaussianDiffuser[tau={self.tau}, sigma=({self.sigma_x}, {self.sigma_y})]"


class LambertianTransmitter(mi.BSDF):
    """The tracer's ``lambertian_transmitter``: rho/pi back to the incident side and tau/pi through,
    about the geometric normal; the side is drawn with probability p = Y(rho) / (Y(rho) + Y(tau)) and
    the direction from a cosine lobe, so the weight is rho/p or tau/(1 - p), as in the tracer.
    Properties: rho, tau (RGB)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        rho, tau = np.array(props["rho"]), np.array(props["tau"])
        yr, yt = float(luminance(rho)), float(luminance(tau))
        self.p_reflect = yr / (yr + yt) if yr + yt > 0 else 1.0
        self.rho, self.tau = mi.Color3f(rho), mi.Color3f(tau)
        self.m_components = [_DIFFUSE_RT]
        self.m_flags = _DIFFUSE_RT

    def _eval_pdf(self, si, wo):
        wi, out = si.to_world(si.wi), si.to_world(wo)
        same = dr.dot(out, si.n) * dr.dot(wi, si.n) > 0
        cos = dr.abs(dr.dot(out, si.n)) / dr.pi
        pdf = dr.select(same, self.p_reflect, 1.0 - self.p_reflect) * cos
        return dr.select(same, self.rho, self.tau) * cos, pdf

    def sample(self, ctx, si, sample1, sample2, active=True):
        wi = si.to_world(si.wi)
        reflect = sample1 < self.p_reflect
        normal = dr.mulsign(si.n, dr.dot(wi, si.n)) * dr.select(reflect, 1.0, -1.0)
        out = mi.Frame3f(normal).to_world(mi.warp.square_to_cosine_hemisphere(sample2))
        bs = mi.BSDFSample3f()
        bs.wo = si.to_local(out)
        bs.pdf = dr.select(reflect, self.p_reflect, 1.0 - self.p_reflect) * dr.dot(out, normal) / dr.pi
        bs.eta = 1.0
        bs.sampled_type = dr.select(reflect, mi.UInt32(+mi.BSDFFlags.DiffuseReflection),
                                    mi.UInt32(+mi.BSDFFlags.DiffuseTransmission))
        bs.sampled_component = mi.UInt32(0)
        weight = dr.select(reflect, self.rho / max(self.p_reflect, 1e-300),
                           self.tau / max(1.0 - self.p_reflect, 1e-300))
        return bs, dr.select(active, weight, mi.Color3f(0.0))

    def eval(self, ctx, si, wo, active=True):
        return dr.select(active, self._eval_pdf(si, wo)[0], mi.Color3f(0.0))

    def pdf(self, ctx, si, wo, active=True):
        return dr.select(active, self._eval_pdf(si, wo)[1], 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        value, pdf = self._eval_pdf(si, wo)
        return dr.select(active, value, mi.Color3f(0.0)), dr.select(active, pdf, 0.0)

    def to_string(self):
        return f"LambertianTransmitter[rho={self.rho}, tau={self.tau}]"


class ThinLensEye(mi.Sensor):
    """Mitsuba's ``thinlens`` camera on the eye's own pixel grid (see the module docstring).

    Camera frame (``to_world`` columns): x = the eye's left, y = its up, z = the gaze, origin at the
    pupil centre (Mitsuba's look_at frame). A film position (u, v) in [0, 1]^2 (v down) is the
    tangent-plane point p = ((1 - 2u) tan_x, (1 - 2v) tan_y), i.e. the tracer's pixel grid
    (tracer/transport/eye.py) with x mirrored to the left, as in thinlens.cpp; a lens point a
    (uniform on the disk of radius ``aperture_radius``, mm) looks toward the point of the focal plane
    that images at p: direction ~ (p - a / s, 1), with 1/s = ``inv_focus_distance`` (0 at infinity).
    The ray's weight is 1 and, for the particle tracer, the importance of a point seen from the lens
    point a along a direction of cosine c to the gaze is 1 / (4 tan_x tan_y c^3 dist^2) with the
    lens-area pdf dist^2 / (pi r^2 c): both as in Mitsuba's thinlens.cpp.
    """

    def __init__(self, props):
        mi.Sensor.__init__(self, props)
        self.tan_x, self.tan_y = props["tan_x"], props["tan_y"]
        self.radius = props["aperture_radius"]
        self.inv_s = props["inv_focus_distance"]
        size = self.film().size()
        self.width, self.height = int(size[0]), int(size[1])
        self.m_needs_sample_3 = True

    def sample_ray(self, time, wavelength_sample, position_sample, aperture_sample, active=True):
        px = (1.0 - 2.0 * position_sample.x) * self.tan_x
        py = (1.0 - 2.0 * position_sample.y) * self.tan_y
        a = self.radius * mi.warp.square_to_uniform_disk_concentric(aperture_sample)
        d = dr.normalize(mi.Vector3f(px - a.x * self.inv_s, py - a.y * self.inv_s, 1.0))
        ray = mi.Ray3f(self.m_to_world @ mi.Point3f(a.x, a.y, 0.0), self.m_to_world @ d)  # maxt: the largest float
        ray.time = time
        return ray, mi.Color3f(1.0)

    def sample_ray_differential(self, time, wavelength_sample, position_sample, aperture_sample, active=True):
        ray, weight = self.sample_ray(time, wavelength_sample, position_sample, aperture_sample, active)
        return mi.RayDifferential3f(ray), weight

    def sample_direction(self, it, sample, active=True):
        local = self.m_to_world.inverse() @ it.p
        a = self.radius * mi.warp.square_to_uniform_disk_concentric(sample)
        v = mi.Vector3f(local.x - a.x, local.y - a.y, local.z)
        dist = dr.norm(v)
        v = v / dist
        ct = v.z
        px = a.x * self.inv_s + v.x / ct
        py = a.y * self.inv_s + v.y / ct
        u = 0.5 * (1.0 - px / self.tan_x)
        w = 0.5 * (1.0 - py / self.tan_y)
        valid = active & (ct > 0) & (u >= 0) & (u <= 1) & (w >= 0) & (w <= 1)
        ds = mi.DirectionSample3f()
        ds.time, ds.delta = it.time, mi.Bool(False)
        ds.uv = mi.Point2f(u * self.width, w * self.height)
        ds.p = self.m_to_world @ mi.Point3f(a.x, a.y, 0.0)
        ds.d = (ds.p - it.p) / dist
        ds.dist = dist
        ds.n = self.m_to_world @ mi.Vector3f(0.0, 0.0, 1.0)
        ds.pdf = dr.select(valid, dist * dist / (dr.pi * self.radius**2 * ct), 0.0)
        importance = 1.0 / (4.0 * self.tan_x * self.tan_y * ct * ct * ct * dist * dist)
        return ds, dr.select(valid, mi.Color3f(importance), mi.Color3f(0.0))

    def bbox(self):
        p = self.m_to_world @ mi.ScalarPoint3f(0.0)
        return mi.ScalarBoundingBox3f(p, p)

    def to_string(self):
        return f"ThinLensEye[tan=({self.tan_x}, {self.tan_y}), aperture_radius={self.radius}]"


mi.register_bsdf("hud_diffuser", GaussianDiffuser)
mi.register_bsdf("hud_lambertian_transmitter", LambertianTransmitter)
mi.register_sensor("hud_eye", ThinLensEye)


def _rgb(value) -> dict:
    return {"type": "rgb", "value": [float(c) for c in np.broadcast_to(value, 3)]}


def _raw_bitmap(image: np.ndarray, filter_type: str = "nearest") -> dict:
    """A texture of linear values as they are (no sRGB decoding, no range check)."""
    return {"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32)), "raw": True,
            "filter_type": filter_type, "wrap_mode": "clamp"}


def _black() -> dict:
    return {"type": "diffuse", "reflectance": _rgb(0.0)}


#: The fields of each material that :func:`bsdf` reads (checked against the schema at import).
MAPPED_FIELDS = {
    "mirror": {"reflectance", "metal"}, "dielectric": {"ior", "ior_outside"},
    "coating": {"reflectance", "transmittance", "reflectance_s", "reflectance_p", "transmittance_s", "transmittance_p"},
    "absorber": set(), "aperture": set(), "lambertian": {"reflectance"},
    "lambertian_transmitter": {"reflectance", "transmittance"}, "diffuser": {"transmittance", "sigma_deg"},
    "lcd": {"image", "image_encoding", "transmittance", "contrast_ratio", "polariser"},
    "retarder": {"transmittance", "axis_deg", "retardance_deg"},
}


class Unpolarised(ValueError):
    """An element that the RGB variants cannot model (benchmarks/mitsuba_polarised.py compares the
    polarised model with Mitsuba's polarised variant)."""


def check_against_schema():
    """Raise if the tracer's schema has a material, or a field of one, that this converter does not map."""
    missing = set(MATERIALS) - set(MAPPED_FIELDS)
    if missing:
        raise NotImplementedError(f"mitsuba_scene.py has no mapping for the material(s) {sorted(missing)}")
    for name, cls in MATERIALS.items():
        unread = {f.name for f in cls.schema.fields} - MAPPED_FIELDS[name]
        if unread:
            raise NotImplementedError(f"mitsuba_scene.py ignores the field(s) {sorted(unread)} of {name!r}")


check_against_schema()


def lcd_cells(params: dict) -> np.ndarray:
    """(H, W, 3) transmittance of every LCD cell: transmittance (1/CR + (1 - 1/CR) image), as the
    tracer's LCD (tracer/optics/materials.py); the image was decoded by its encoding at load."""
    cr = params["contrast_ratio"]
    return params["transmittance"] * (1.0 / cr + (1.0 - 1.0 / cr) * params["image"])


def bsdf(obj: SceneObject) -> dict:
    """The Mitsuba BSDF dict of a traced object's material (module docstring)."""
    m = obj.material
    p = m.params
    polarising = (m.type == "retarder" or (m.type == "lcd" and p.get("polariser") is not None)
                  or (m.type == "coating" and "reflectance_s" in p))
    if polarising:
        raise Unpolarised(f"{obj.name}: a {m.type} that polarises has no equivalent in Mitsuba's {VARIANT} variant")
    if m.type == "mirror" and p.get("metal") is not None:
        n, k = (float(x) for x in p["metal"]["complex_ior"])
        r0 = abs((1 - complex(n, k)) / (1 + complex(n, k))) ** 2  # the tracer's reflectance is R(0)
        return {"type": "twosided", "bsdf": {"type": "conductor", "eta": n, "k": k,
                                             "specular_reflectance": _rgb(np.asarray(p["reflectance"]) / r0)}}
    if m.type == "mirror":
        return {"type": "twosided", "bsdf": {"type": "conductor", "material": "none",
                                             "specular_reflectance": _rgb(p["reflectance"])}}
    if m.type == "dielectric":
        return {"type": "dielectric", "int_ior": p["ior"], "ext_ior": p["ior_outside"]}
    if m.type == "lcd":
        return {"type": "thindielectric", "int_ior": 1.0, "ext_ior": 1.0,
                "specular_reflectance": _rgb(0.0), "specular_transmittance": _raw_bitmap(lcd_cells(p))}
    if m.type == "coating":
        yr, yt = float(luminance(p["reflectance"])), float(luminance(p["transmittance"]))
        if yt == 0:
            return {"type": "twosided", "bsdf": {"type": "conductor", "material": "none",
                                                 "specular_reflectance": _rgb(p["reflectance"])}}
        p_t = yt / (yr + yt)
        passing = {"type": "thindielectric", "int_ior": 1.0, "ext_ior": 1.0, "specular_reflectance": _rgb(0.0),
                   "specular_transmittance": _raw_bitmap(np.reshape(p["transmittance"] / p_t, (1, 1, 3)))}
        if yr == 0:
            return passing
        reflecting = {"type": "twosided", "bsdf": {
            "type": "conductor", "material": "none",
            "specular_reflectance": _raw_bitmap(np.reshape(p["reflectance"] / (1 - p_t), (1, 1, 3)))}}
        return {"type": "blendbsdf", "weight": p_t, "bsdf_0": reflecting, "bsdf_1": passing}
    if m.type == "lambertian":
        return {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": _rgb(p["reflectance"])}}
    if m.type == "lambertian_transmitter":
        return {"type": "hud_lambertian_transmitter", "rho": mi.ScalarColor3f(p["reflectance"]),
                "tau": mi.ScalarColor3f(p["transmittance"])}
    if m.type == "diffuser":
        sigma = np.sin(np.radians(p["sigma_deg"]))  # direction cosines, as tracer GaussianDiffuser
        return {"type": "hud_diffuser", "tau": mi.ScalarColor3f(p["transmittance"]),
                "sigma_x": float(sigma[0]), "sigma_y": float(sigma[1]), "axis": mi.ScalarVector3f(obj.local_x)}
    if m.type == "absorber":
        return _black()
    raise ValueError(f"{obj.name}: material {m.type!r} has no Mitsuba mapping")


def _mesh(name: str, vertices: np.ndarray, faces: np.ndarray, bsdf_dict: dict, emitter: dict | None = None,
          normals: np.ndarray | None = None, uv: np.ndarray | None = None) -> mi.Mesh:
    """A Mitsuba mesh of world-space triangles (mm), with its BSDF and emitter."""
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf_dict)
    if emitter is not None:
        props["emitter"] = mi.load_dict(emitter)
    mesh = mi.Mesh(name, len(vertices), len(faces), props, normals is not None, uv is not None)
    params = mi.traverse(mesh)
    buffers = {"vertex_positions": (vertices, np.float32), "faces": (faces, np.uint32),
               "vertex_normals": (normals, np.float32), "vertex_texcoords": (uv, np.float32)}
    for key, (data, dtype) in buffers.items():
        if data is not None:  # the buffer's own type: a JIT array, or a dynamic array in the scalar variant
            params[key] = type(params[key])(np.ascontiguousarray(data, dtype=dtype).ravel())
    params.update()
    return mesh


def _shapes(obj: SceneObject) -> dict:
    """The Mitsuba shapes of one traced object: one mesh, two for a two-sided emitter."""
    normals = obj.normals if obj.smooth else None
    # Mitsuba's bitmap has row 0 at v = 0; the tracer's (OBJ) texture coordinates have v up.
    uv = None if obj.uv is None else np.stack([obj.uv[:, 0], 1.0 - obj.uv[:, 1]], axis=1)
    if obj.emission is None or obj.emission.luminance <= 0:
        return {obj.name: _mesh(obj.name, obj.vertices, obj.faces, bsdf(obj), None, normals, uv)}
    if obj.emission.polarisation is not None:
        raise Unpolarised(f"{obj.name}: polarised emission has no equivalent in Mitsuba's {VARIANT} variant")
    emitter = {"type": "area", "radiance": _rgb(obj.emission.radiance)}
    if not obj.emission.two_sided:
        return {obj.name: _mesh(obj.name, obj.vertices, obj.faces, bsdf(obj), emitter, normals, uv)}
    tri = obj.triangles
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    face_n /= np.linalg.norm(face_n, axis=1, keepdims=True)
    eps = TWO_SIDED_OFFSET * (1.0 + float(np.abs(obj.vertices).max()))
    faces = np.arange(3 * len(tri)).reshape(-1, 3)
    front = (tri + eps * face_n[:, None, :]).reshape(-1, 3)
    back = (tri - eps * face_n[:, None, :]).reshape(-1, 3)
    return {obj.name: _mesh(obj.name, front, faces, bsdf(obj), emitter),
            f"{obj.name}__back": _mesh(f"{obj.name}__back", back, faces[:, ::-1], bsdf(obj), emitter)}


def environment(scene: Scene) -> dict | None:
    """The Mitsuba emitter dict of the scene's environment, or None (module docstring). A sun (a disk of
    finite size, tracer.sources.sun.EnvironmentWithSun) has no Mitsuba counterpart here: refused."""
    env = scene.environment
    if isinstance(env, EnvironmentWithSun):
        raise NotImplementedError(f"{scene.name}: the Mitsuba peer does not convert the environment's sun (a disk "
                                  "of finite angular size)")
    if isinstance(env, UniformEnvironment):
        return {"type": "constant", "radiance": _rgb(env.luminance_cd_m2 * env.color)}
    if isinstance(env, HdriEnvironment):
        pixels = read_image(scene.root / scene.raw["environment"]["file"])
        rgb = np.repeat(pixels[..., :1], 3, axis=2) if pixels.shape[2] <= 2 else pixels[..., :3]
        a = math.radians(env.rotation_deg)
        rot_z = np.array([[math.cos(a), -math.sin(a), 0, 0], [math.sin(a), math.cos(a), 0, 0], [0, 0, 1, 0],
                          [0, 0, 0, 1]])
        y_up_to_z_up = np.array([[0, 0, 1, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1]], dtype=float)
        return {"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(rgb, dtype=np.float32)),
                "scale": env.scale_factor, "to_world": mi.ScalarTransform4f(rot_z @ y_up_to_z_up)}
    return None


def sensor(scene: Scene) -> dict:
    """The :class:`ThinLensEye` dict of the scene's eye, with a box-filtered RGB film."""
    e = scene.eye
    gaze = e.gaze / np.linalg.norm(e.gaze)
    left = np.cross(e.up, gaze)
    left /= np.linalg.norm(left)
    frame = np.eye(4)
    frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3] = left, np.cross(gaze, left), gaze, e.position
    return {"type": "hud_eye", "to_world": mi.ScalarTransform4f(frame),
            "tan_x": math.tan(math.radians(e.fov_deg[0]) / 2), "tan_y": math.tan(math.radians(e.fov_deg[1]) / 2),
            "aperture_radius": 0.5 * e.pupil_diameter_mm,
            "inv_focus_distance": 0.0 if math.isinf(e.accommodation_distance_mm) else 1.0 / e.accommodation_distance_mm,
            "film": {"type": "hdrfilm", "width": e.resolution[0], "height": e.resolution[1],
                     "rfilter": {"type": "box"}, "pixel_format": "rgb", "component_format": "float32",
                     "sample_border": False},
            "sampler": {"type": "independent", "sample_count": 1}}


def scene_dict(scene: Scene) -> dict:
    """The whole scene as a dict for ``mi.load_dict``: sensor, shapes (apertures left out), environment."""
    if scene.eye.analyser is not None:
        raise Unpolarised(f"the eye's analyser has no equivalent in Mitsuba's {VARIANT} variant")
    d = {"type": "scene", "eye": sensor(scene)}
    for obj in scene.traced_objects:
        d.update(_shapes(obj))
    env = environment(scene)
    if env is not None:
        d["environment"] = env
    return d


def load(scene: Scene) -> mi.Scene:
    """The loaded Mitsuba scene of a tracer scene."""
    return mi.load_dict(scene_dict(scene))


def integrator(scene: Scene, kind: str) -> mi.Integrator:
    """Mitsuba's ``path`` (camera paths; the scene's methods.backward.max_depth) or ``ptracer``
    (particles; methods.forward.max_depth). Both count max_depth in ray segments, as the tracer does;
    Russian roulette is switched off (rr_depth = max_depth), as the tracer's only thins paths that can
    no longer change a pixel by 1e-4 of the image's mean luminance."""
    depth = scene.method_options("backward" if kind == "path" else "forward")["max_depth"]
    return mi.load_dict({"type": kind, "max_depth": depth, "rr_depth": depth, "hide_emitters": False})
