"""Aiming targets: the pdf a target reports for a direction equals the density its sampler draws
(checked exactly through the change of variables dA = dist^2 / |cos| dOmega, and by chi-square)."""

import numpy as np

from presets._build import frame_matrix, rectangle
from tests.support.chi2 import ChiSquareTest
from tracer.core.sampling import make_rng
from tracer.transport.apertures import MeshTarget


def _target():
    v, f, _ = rectangle(30.0, 10.0)
    m = np.array(frame_matrix([5.0, 200.0, 3.0], [1, 0, 0], [0.2, -1, 0.1]))
    return MeshTarget((v @ m[:3, :3].T + m[:3, 3])[f]), m


def test_mesh_target_pdf_matches_its_sampler_exactly():
    target, _ = _target()
    origins = make_rng(1).normal(0, 20, (3, 5000))
    d, pdf = target.sample(origins, make_rng(2).random((3, 5000)))
    np.testing.assert_allclose(target.pdf(origins, d), pdf, rtol=1e-6)
    # Solid-angle density times dOmega/dA gives the uniform area density 1/A.
    hit_t = target._accel.intersect(origins, d).t
    cos = np.abs(target.normal[:, 0] @ d)
    np.testing.assert_allclose(pdf * cos / hit_t**2, 1 / target.area, rtol=1e-6)
    # Directions that miss the aperture have zero density.
    assert np.all(target.pdf(origins, -d) == 0)


def test_mesh_target_directions_chi2():
    """Directions from one origin, histogrammed by where they cross the aperture (its own (s, t) in
    [0, 1]^2), against the density the reported pdf implies there: pdf * |cos| * A / dist^2."""
    target, m = _target()
    origin = np.zeros((1, 3))
    ex, ey, c = m[:3, 0] * 30.0, m[:3, 1] * 10.0, m[:3, 3]  # rectangle edges and centre
    normal = target.normal[:, 0]

    def to_st(d):
        t = ((c - origin) @ normal) / (d @ normal)
        p = origin + t[:, None] * d - (c - 0.5 * ex - 0.5 * ey)
        return np.stack([p @ ex / (ex @ ex), p @ ey / (ey @ ey)], axis=1)

    def sample(n, rng):
        d, _ = target.sample(np.repeat(origin.T, n, 1), rng.random((3, n)))
        return to_st(d.T), np.ones(n, bool)

    def density(s, t):
        p = c + (s[:, None] - 0.5) * ex + (t[:, None] - 0.5) * ey - origin
        dist = np.linalg.norm(p, axis=1)
        d = p / dist[:, None]
        return target.pdf(np.repeat(origin.T, len(s), 1), d.T) * np.abs(d @ normal) * target.area / dist**2

    test = ChiSquareTest(((0.0, 1.0), (0.0, 1.0)), (30, 10), sample, density, sample_count=300_000, seed=3)
    ok, msg = test.run()
    assert ok, msg
