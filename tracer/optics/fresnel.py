"""Specular laws: reflection, refraction and Fresnel reflectance of a dielectric interface.

Fresnel equations: the s and p amplitudes (what polarised transport uses, tracer.optics.polar), and
for unpolarised light R = (R_s + R_p) / 2 with
r_s = (n1 cos_i - n2 cos_t) / (n1 cos_i + n2 cos_t), r_p = (n2 cos_i - n1 cos_t) / (n2 cos_i + n1 cos_t)
(Born & Wolf, Principles of Optics, 7th ed., sec. 1.5.2, doi:10.1017/CBO9781139644181).
Vectors are (3, n) planes (:mod:`tracer.core.vec`).
"""

from __future__ import annotations

import numpy as np

from ..core.vec import normalize, reflect  # noqa: F401  (reflect is part of this module's interface)


def fresnel_amplitudes(cos_i: np.ndarray, eta: np.ndarray | float):
    """Real Fresnel amplitude coefficients of a dielectric interface, in the precision of ``cos_i``.

    r_s = (cos_i - eta cos_t) / (cos_i + eta cos_t), r_p = (eta cos_i - cos_t) / (eta cos_i + cos_t)
    (Born & Wolf sec. 1.5.2; the p basis vector k x s on both rays, tracer.optics.polar); the
    transmission amplitudes follow as t_s = 1 + r_s and t_p = (1 + r_p) / eta.

    Returns
    -------
    r_s, r_p : (n,); where ``tir`` both are 1 (their phases are tracer.optics.polar.amplitudes').
    cos_t : (n,) cosine of the refraction angle (0 under total internal reflection).
    tir : (n,) bool, total internal reflection.
    """
    cos_i = np.clip(cos_i, 0, 1)
    sin2_t = (1 - cos_i * cos_i) / (eta * eta)
    tir = sin2_t >= 1
    cos_t = np.sqrt(np.clip(1 - sin2_t, 0, 1))
    # Both denominators vanish only at grazing incidence under total internal reflection (cos_i =
    # cos_t = 0), where R = 1 is taken: divide by 1 there instead of making 0/0.
    den_s, den_p = cos_i + eta * cos_t, eta * cos_i + cos_t
    rs = (cos_i - eta * cos_t) / np.where(den_s > 0, den_s, 1)
    rp = (eta * cos_i - cos_t) / np.where(den_p > 0, den_p, 1)
    return rs, rp, cos_t, tir


def fresnel_unpolarized(cos_i: np.ndarray, eta: np.ndarray | float):
    """Reflectance of a dielectric interface for unpolarised light.

    Parameters
    ----------
    cos_i : (n,) cosine of the angle of incidence, in [0, 1] (the results keep its precision).
    eta : n_t / n_i, scalar or (n,).

    Returns
    -------
    R : (n,) reflectance (1 under total internal reflection).
    cos_t : (n,) cosine of the refraction angle (0 under total internal reflection).
    """
    return unpolarized_from_amplitudes(*fresnel_amplitudes(cos_i, eta))


def unpolarized_from_amplitudes(rs: np.ndarray, rp: np.ndarray, cos_t: np.ndarray, tir: np.ndarray):
    """(R, cos_t) of :func:`fresnel_unpolarized` from :func:`fresnel_amplitudes`' results."""
    r = 0.5 * (rs * rs + rp * rp)
    return np.where(tir, 1, r), np.where(tir, 0, cos_t)


def refract(d: np.ndarray, n: np.ndarray, eta: np.ndarray | float, cos_i: np.ndarray, cos_t: np.ndarray) -> np.ndarray:
    """Refracted direction (Snell), (3, n), of unit ``d`` through a surface whose unit normal ``n``
    faces the incident side (d . n = -cos_i); eta = n_t / n_i."""
    inv = 1 / eta
    return normalize(d * inv + (cos_i * inv - cos_t) * n)
