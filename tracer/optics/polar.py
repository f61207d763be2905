"""Polarisation: Stokes vectors carried along paths, Mueller matrices at interactions.

Light of a ray travelling along the unit vector k is described by its Stokes vector S = (S0, S1, S2,
S3) in a reference frame (x, y = k x x), x perpendicular to k: S0 the intensity, S1 = I_x - I_y,
S2 = I_(+45) - I_(-45), S3 the circular part (Born & Wolf, Principles of Optics, 7th ed., sec. 10.8,
doi:10.1017/CBO9781139644181; Collett, Field Guide to Polarization, doi:10.1117/3.626141). An
interaction maps it by a 4 x 4 Mueller matrix, M, written in frames of the incident and the
outgoing ray; a change of frame (x rotated by phi about k) is the rotator
S1' = cos 2phi S1 + sin 2phi S2, S2' = -sin 2phi S1 + cos 2phi S2.

How the tracer carries it (in the manner of Mitsuba 3's polarised variants, Jakob et al.,
``mitsuba/core/mueller.h``; Wilkie and Weidlich, "Polarised light in computer graphics", SIGGRAPH Asia
2012 course, doi:10.1145/2407783.2407790):

- a path's RGB weight ``beta`` is S0 (per channel), and ``extra["stokes"]`` (3, C, n) holds the
  normalised S1..S3 / S0 in the frame ``extra["frame"]`` (3, n): C = 1, one state for the three
  channels, where every Mueller matrix of the scene is achromatic (Fresnel surfaces of one index,
  metals, polarisers, retarders: the state then stays the same in every channel), C = 3 where a
  coating's s/p values differ by channel;
- light paths (forward tracing, photons) carry the Stokes vector of their light, S' = M S;
- camera paths (backward tracing, the brightness-theorem analysis) carry the row vector that the
  detector applies to the light arriving along the path (its analyser's first Mueller row; (1, 0, 0,
  0) for the eye), r' = r M: what a path meets is then r . S_emitted. The frame of a camera path is
  that of the light travelling *toward* the eye along it (k = -d);
- materials give M normalised by its first element (:class:`Mueller`: M / M00) because their scalar
  weight (the unpolarised f cos / pdf the other methods use) is M00 times the sampling factor; a
  material's ``mueller(it, k_in, k_out, flags)`` says what its sampled lobe does;
- every scattering (non-delta) lobe depolarises (Lambertian surfaces, the screens and diffusers:
  volume scattering), so next-event estimation and photon maps, which connect only at such lobes, need
  the path's S0 alone;
- a scene with no element that polarises (no dielectric, coating with s/p data, metal mirror, LCD
  polariser, polarised emitter or analyser at the eye) carries nothing (``World.polar`` is None).

Most Mueller matrices of optics have the form (normalised)

    [[1, b, 0, 0], [b, 1, 0, 0], [0, 0, c, d], [0, 0, -d, c]]

in a frame whose x is the element's axis (the s direction of a plane of incidence, a film's fast
axis): diattenuation b = (T_x - T_y) / (T_x + T_y), and c, d from the amplitude ratio and the
retardance. Fresnel reflection and refraction, metals, coatings, retarders and linear diattenuators
(a polariser sheet, polarised sunglasses) all have it (:func:`sp_apply` applies it to Stokes vectors;
:meth:`Transport.scatter` to the normalised states paths carry); the LCD's output polariser,
which passes a share of the light whatever its state and leaves it polarised along its axis, and
depolarisation are the two other kinds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.sampling import frame_from_normal
from ..core.vec import F32, cross, dot, take

#: Kinds of :class:`Mueller`.
SP, POLARISE, DEPOLARISE = "sp", "polarise", "depolarise"


@dataclass
class Mueller:
    """A normalised Mueller matrix (M / M00) for a batch of interactions.

    kind : :data:`SP` (the form of the module docstring, with ``b``, ``c``, ``d``: (n,), (3, n) per
    channel, or scalars), :data:`POLARISE` (output fully polarised along x whatever the input:
    M = [[1, 0, 0, 0], [1, 0, 0, 0], 0, 0]) or :data:`DEPOLARISE` (M = diag(1, 0, 0, 0)).
    x_in, x_out : (3, n) frames (x vectors) of the incident and the outgoing light in which M is written.
    """

    kind: str
    x_in: np.ndarray | None = None
    x_out: np.ndarray | None = None
    b: object = 0.0
    c: object = 1.0
    d: object = 0.0


def any_frame(k: np.ndarray) -> np.ndarray:
    """A frame x (3, n) perpendicular to unit directions k (3, n) (Duff et al.'s basis)."""
    return frame_from_normal(k)[0].astype(F32)


def axis_frame(axis: np.ndarray, k: np.ndarray) -> np.ndarray:
    """The frame x (3, n) along ``axis`` ((3,) or (3, n)) projected perpendicular to k; where the axis
    is (nearly) along k, any perpendicular."""
    return frame_from_normal(k, axis)[0].astype(F32)


def s_frame(k_in: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The s direction (3, n) of the plane of incidence of k_in on a surface of unit normals ``normal``:
    k_in x n normalised (perpendicular to every ray in that plane); at normal incidence, where the
    plane is undefined, any direction perpendicular to k_in (every frame is an s/p frame there)."""
    s = cross(k_in, normal)
    length = np.sqrt(dot(s, s))
    ok = length > 1e-6
    out = s * (1 / np.where(ok, length, 1))
    if not np.all(ok):
        out = np.where(ok, out, any_frame(k_in))
    return out.astype(F32)


def rotation(x_from: np.ndarray, x_to: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cos 2phi, sin 2phi) (n,) of the rotation about k that takes frame x_from to x_to (both
    perpendicular to k)."""
    c = dot(x_from, x_to)
    s = dot(cross(x_from, x_to), k)
    r2 = c * c + s * s
    inv = 1 / np.where(r2 > 0, r2, 1)
    return (c * c - s * s) * inv, 2 * c * s * inv


def state_s1(state: tuple, x: np.ndarray, k: np.ndarray) -> np.ndarray:
    """S1 / S0 (C, n) of paths' states ``state`` = (stokes (3, C, n), frame (3, n)) re-written in the
    frame x (3, n) about the light's direction k: what a diattenuator with axis x makes of them
    (S0' / S0 = 1 + b s1)."""
    stokes, frame = state
    c2, s2 = rotation(frame, x, k)
    return c2 * stokes[0] + s2 * stokes[1]


def rotate(stokes: np.ndarray, x_from: np.ndarray, x_to: np.ndarray, k: np.ndarray) -> np.ndarray:
    """S1..S3 (3, C, n) (or (3, n)) written in frame x_from, re-written in x_to (rotation about k).
    Row vectors of camera paths rotate the same way (the rotator is orthogonal)."""
    c2, s2 = rotation(x_from, x_to, k)
    out = np.empty_like(stokes)
    out[0] = c2 * stokes[0] + s2 * stokes[1]
    out[1] = c2 * stokes[1] - s2 * stokes[0]
    out[2] = stokes[2]
    return out


def sp_apply(s0: np.ndarray, stokes: np.ndarray, b, c, d, row: bool) -> tuple[np.ndarray, np.ndarray]:
    """Apply the form [[1, b, 0, 0], [b, 1, 0, 0], [0, 0, c, d], [0, 0, -d, c]] to Stokes vectors (s0 (C, n),
    S1..S3 (3, C, n)), not normalised (what checks of a material's matrix use); ``row``: to a row vector
    from the right (r M), which transposes the retardance term."""
    s1, s2, s3 = stokes
    if row:
        d = -d
    out = np.empty_like(stokes)
    out[0] = b * s0 + s1
    out[1] = c * s2 + d * s3
    out[2] = c * s3 - d * s2
    return s0 + b * s1, out


def amplitudes(cos_i: np.ndarray, eta) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fresnel amplitude coefficients of an interface, complex: (r_s, r_p, t_s, t_p) (n,).

    ``eta`` = n_t / n_i, real (a dielectric; under total internal reflection |r| = 1 with the phase of
    Born & Wolf sec. 1.5.4) or complex n + i kappa (a metal, Born & Wolf sec. 14.2). Convention:
    r_s = (cos_i - eta cos_t) / (cos_i + eta cos_t), r_p = (eta cos_i - cos_t) / (eta cos_i + cos_t),
    t_s = 2 cos_i / (cos_i + eta cos_t), t_p = 2 cos_i / (eta cos_i + cos_t), with the p basis vector
    k x s on both rays (so that at normal incidence r_p = -r_s: the same reflection of the field)."""
    cos_i = np.clip(np.asarray(cos_i, np.float64), 0.0, 1.0)
    eta = np.asarray(eta, np.complex128)
    sin2_t = (1 - cos_i * cos_i) / (eta * eta)
    cos_t = np.sqrt(1 - sin2_t)
    cos_t = np.where(cos_t.imag < 0, -cos_t, cos_t)  # the evanescent (decaying) root
    den_s, den_p = cos_i + eta * cos_t, eta * cos_i + cos_t
    den_s = np.where(den_s != 0, den_s, 1)
    den_p = np.where(den_p != 0, den_p, 1)
    return ((cos_i - eta * cos_t) / den_s, (eta * cos_i - cos_t) / den_p, 2 * cos_i / den_s, 2 * cos_i / den_p)


def sp_from_amplitudes(a_s: np.ndarray, a_p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(b, c, d) (float32) of the normalised Mueller matrix of amplitude coefficients a_s, a_p (complex):
    b = (|a_s|^2 - |a_p|^2) / (|a_s|^2 + |a_p|^2), c + i d = 2 a_s conj(a_p) / (|a_s|^2 + |a_p|^2)."""
    ps, pp = np.abs(a_s) ** 2, np.abs(a_p) ** 2
    tot = ps + pp
    inv = 1 / np.where(tot > 0, tot, 1)
    cross_term = 2 * a_s * np.conj(a_p) * inv
    return ((ps - pp) * inv).astype(F32), cross_term.real.astype(F32), cross_term.imag.astype(F32)


def sp_from_powers(t_x, t_y, sign: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(b, c, d) of an element that transmits (or reflects) the powers t_x, t_y of light polarised
    along and across its axis, with no retardance (``sign`` -1: the half-turn phase of a reflection,
    as an ideal mirror's r_s = -1, r_p = 1)."""
    t_x, t_y = np.asarray(t_x, np.float64), np.asarray(t_y, np.float64)
    tot = t_x + t_y
    inv = 1 / np.where(tot > 0, tot, 1)
    return ((t_x - t_y) * inv).astype(F32), (sign * 2 * np.sqrt(t_x * t_y) * inv).astype(F32), np.zeros_like(
        tot, dtype=F32)


def analyser_row(transmit_along: float, transmit_across: float) -> tuple[float, float]:
    """The first Mueller row (m0, m1) of a linear polariser (polarised sunglasses) in the frame of its
    axis: m0 = (t_along + t_across) / 2, m1 = (t_along - t_across) / 2 (Malus: polarised light at angle
    theta to the axis passes t_along cos^2 + t_across sin^2)."""
    return 0.5 * (transmit_along + transmit_across), 0.5 * (transmit_along - transmit_across)


def linear(s0: np.ndarray, degree, frame_angle_cos2, frame_angle_sin2) -> np.ndarray:
    """S1..S3 (3, C, n) of light of intensity s0 (C, n) linearly polarised to ``degree`` at the angle
    whose (cos 2phi, sin 2phi) (n,) are given, from the frame's x."""
    out = np.zeros((3,) + s0.shape, F32)
    out[0] = s0 * (degree * frame_angle_cos2)
    out[1] = s0 * (degree * frame_angle_sin2)
    return out


class Transport:
    """What the path loop and the methods do with Stokes vectors in a world that needs them
    (``World.polar``; None elsewhere, so that unpolarised scenes pay nothing).

    Per path: ``extra["stokes"]`` (3, C, n) float32, the normalised S1..S3 / S0 (C = :attr:`channels`),
    and ``extra["frame"]`` (3, n) float32, perpendicular to the path's direction; S0 is the path's
    ``beta`` (module docstring). Normalised, an interaction of the form [[1, b, ...]] scales beta by
    f = 1 + b s1 and the state by 1 / f.
    """

    def __init__(self, world):
        """``world``: the render world (its materials, scene objects and eye, tracer.transport.eye.ThinLensEye)."""
        self.world = world
        #: Channels of the normalised state: 1 where every Mueller matrix is achromatic, else 3.
        self.channels = 3 if any(m.chromatic_polarisation for m in world.materials) else 1
        #: The analyser at the eye (polarised sunglasses): (axis (3,) world, row (m0, m1)) or None.
        self.analyser = None
        eye = world.eye
        if eye.spec.analyser is not None:
            a = eye.spec.analyser
            theta = np.radians(a["axis_deg"])
            self.analyser = (np.cos(theta) * eye.right + np.sin(theta) * eye.up,
                             analyser_row(a["transmittance_along"], a["transmittance_across"]))
        #: Emitters' linear polarisation by object slot: axis (3, slots) world and degree (slots,).
        slots = len(world.scene.objects)
        self.emit_axis = np.zeros((3, slots), F32)
        self.emit_degree = np.zeros(slots, F32)
        for o in world.scene.objects:
            pol = o.emission.polarisation if o.emission is not None else None
            if pol is not None:
                self.emit_axis[:, o.slot] = o.axis(pol["axis_deg"])
                self.emit_degree[o.slot] = pol["degree"]
        self.polarised_emitters = bool(np.any(self.emit_degree > 0))

    def _zero(self, n: int) -> np.ndarray:
        return np.zeros((3, self.channels, n), F32)

    # -- path starts -----------------------------------------------------------------------------
    def start_light(self, beta: np.ndarray, wo: np.ndarray, slot: np.ndarray) -> dict:
        """The extra arrays of particles leaving emitters ``slot`` (n,) along ``wo``: their emitters'
        polarisation (none: unpolarised)."""
        n = len(slot)
        stokes = self._zero(n)
        if not self.polarised_emitters:
            return {"stokes": stokes, "frame": any_frame(wo)}
        stokes[0] = self.emit_degree[slot]
        return {"stokes": stokes, "frame": axis_frame(take(self.emit_axis, slot), wo)}

    def start_camera(self, beta: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, dict]:
        """(beta, extra) of camera paths of weight ``beta`` (3, n) leaving the eye along ``d``: the eye's
        analyser row times beta (an unpolarised detector: (1, 0, 0, 0))."""
        n = d.shape[1]
        stokes = self._zero(n)
        if self.analyser is None:
            return beta, {"stokes": stokes, "frame": any_frame(d)}
        axis, (m0, m1) = self.analyser
        stokes[0] = m1 / m0 if m0 > 0 else 0.0
        return (beta * F32(m0)).astype(F32), {"stokes": stokes, "frame": axis_frame(axis, d)}

    # -- what sensors and sources see ------------------------------------------------------------
    def detect(self, beta: np.ndarray, extra: dict, d: np.ndarray) -> np.ndarray:
        """What the eye's detector takes of light paths (forward) arriving along ``d``: (3, n) S0, or
        the analyser's row applied to the Stokes vector."""
        if self.analyser is None:
            return beta
        axis, (m0, m1) = self.analyser
        c2, s2 = rotation(extra["frame"], axis_frame(axis, d), d)
        s1 = c2 * extra["stokes"][0] + s2 * extra["stokes"][1]
        # A physical state has |s1| <= 1, so the factor is >= t_across >= 0; float32 rounding over a
        # path's interactions takes fully polarised light a little past 1 (1e-5 after the windshield),
        # which a crossed analyser (t_across 0) turned into negative pixels. Clamped as scatter clamps.
        return beta * np.maximum(m0 + m1 * s1, 0)

    def emitted(self, beta: np.ndarray, extra: dict, d: np.ndarray, slot: np.ndarray) -> np.ndarray:
        """The factor (3, n) that replaces ``beta`` when camera paths (row vectors) arriving along ``d``
        meet emitters ``slot``: r . S_e / L_e = r0 (1 + degree (s1 cos 2phi + s2 sin 2phi)), phi the
        angle of the emitter's axis in the path's frame."""
        if not self.polarised_emitters:
            return beta
        degree = self.emit_degree[slot]
        k = -d  # the light travels toward the eye
        c2, s2 = rotation(extra["frame"], axis_frame(take(self.emit_axis, slot), k), k)
        return beta * np.maximum(1 + degree * (c2 * extra["stokes"][0] + s2 * extra["stokes"][1]), 0)

    # -- interactions ----------------------------------------------------------------------------
    def scatter(self, beta: np.ndarray, extra: dict, it, bsdf, wo: np.ndarray, weight, flags: np.ndarray,
                importance: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(beta, stokes, frame) after the lobe ``flags`` of material ``bsdf`` sends paths of weight
        ``beta`` (3, n) arriving as ``it`` along ``wo`` with the scalar weight ``weight`` (the sample's
        f cos / pdf): M S for light paths (``importance``), r M for camera paths."""
        stokes, frame = extra["stokes"], extra["frame"]
        if importance:
            k_in, k_out = it.d, wo
        else:
            k_in, k_out = -wo, -it.d
        m = bsdf.mueller(it, k_in, k_out, flags)
        w = beta * np.asarray(weight, F32)
        if m is None:  # identity, the ray undeviated
            return w, stokes, frame
        if m.kind == DEPOLARISE:
            return w, np.zeros_like(stokes), any_frame(wo)
        if importance:
            rot = rotate(stokes, frame, m.x_in, k_in)
            new_frame = m.x_out
        else:
            rot = rotate(stokes, frame, m.x_out, k_out)
            new_frame = m.x_in
        out = np.zeros_like(stokes)
        if m.kind == POLARISE:
            if importance:  # fully polarised along the axis, whatever arrived
                out[0] = 1
                return w, out, new_frame
            return w * np.maximum(1 + rot[0], 0), out, new_frame
        s1, s2, s3 = rot
        f = np.maximum(1 + m.b * s1, 0)
        inv = np.where(f > 1e-12, 1 / np.where(f > 1e-12, f, 1), 0)
        d = -m.d if not importance else m.d
        out[0] = (m.b + s1) * inv
        out[1] = (m.c * s2 + d * s3) * inv
        out[2] = (m.c * s3 - d * s2) * inv
        return (w * f).astype(F32), out, new_frame
