"""Exact surfaces in the path loop (tracer/transport/surfaces.py through the accelerator and the world):
hits on a meshed sphere are moved onto the sphere and take its normal, reflected rays leave beyond the
facets, an affine transform carries the shape with the mesh, and the mesh alone is what it was."""

import numpy as np
import pytest

from presets._build import frame_matrix
from tests.support.scenes import sphere_mirror_scene
from tracer.core.vec import F32
from tracer.optics.materials import mirror_directions
from tracer.scene import load_scene
from tracer.transport.world import World

R = 500.0


def _rays(n=20000, seed=1, z=300.0):
    rng = np.random.default_rng(seed)
    o = np.stack([rng.uniform(-50, 50, n), rng.uniform(-50, 50, n), np.full(n, z)])
    d = np.zeros((3, n), F32)
    d[2] = -1
    return o, d


def _hits(world, o, d):
    h = world.accel.intersect(o, d)
    p = o + h.t * d
    return h, p, world.interaction(h.face, p, d)


def _angle(a, b):
    """Angles (n,) rad between unit vectors (3, n), accurate near 0."""
    return np.linalg.norm(np.cross(a.T.astype(float), b.T.astype(float)), axis=1)


@pytest.fixture(scope="module")
def mirror(tmp_path_factory):
    return load_scene(sphere_mirror_scene(tmp_path_factory.mktemp("sphere")))


def test_faces_are_assigned_with_their_gap(mirror):
    s = mirror.objects[0].surfaces[0]
    assert len(s.faces) == len(mirror.objects[0].faces)
    # a facet's sagitta: cells 10 mm wide on a 500 mm sphere, about (10 sqrt 2)^2 / (8 R) at the diagonal
    assert 0.02 < s.gap_mm.max() < 0.06


def test_hits_lie_on_the_sphere_with_its_normal(mirror):
    centre = np.array([[0.0], [0.0], [R]])
    o, d = _rays()
    exact, mesh = World(mirror), World(mirror, exact_surfaces=False)
    h, p, it = _hits(exact, o, d)
    assert (h.face >= 0).all()
    np.testing.assert_allclose(np.linalg.norm(p - centre, axis=0), R, rtol=0, atol=1e-9)
    true_n = (centre - p) / R
    assert _angle(it.ng, true_n).max() < 1e-6 and _angle(it.ns, true_n).max() < 1e-6
    assert exact.accel.surfaces.refined == len(h.face) and exact.accel.surfaces.kept == 0
    # the mesh alone: hits on the chords, facet normals off by mrad, interpolated ones by tens of urad
    _, pm, itm = _hits(mesh, o, d)
    assert np.abs(np.linalg.norm(pm - centre, axis=0) - R).max() > 0.02
    assert _angle(itm.ng, (centre - pm) / np.linalg.norm(centre - pm, axis=0)).max() > 5e-3


def test_reflected_rays_leave_beyond_the_facets(mirror):
    """Rays reflected on the concave side, where the facets lie in front of the sphere, meet nothing."""
    world = World(mirror)
    o, d = _rays()
    h, p, it = _hits(world, o, d)
    wo = mirror_directions(it)
    again = world.accel.intersect(world.accel.spawn(p, it.ng, wo, it.offset), wo)
    assert (again.face < 0).all()
    # at grazing incidence too: rays along x skim the cap's rim
    o2 = np.stack([np.full(400, -80.0), np.zeros(400), np.linspace(15, 5, 400)])
    d2 = np.tile(np.array([[1.0], [0.0], [-0.02]], F32), 400)
    d2 /= np.linalg.norm(d2, axis=0)
    h2 = world.accel.intersect(o2, d2)
    k = h2.face >= 0
    p2 = o2[:, k] + h2.t[k] * d2[:, k]
    it2 = world.interaction(h2.face[k], p2, d2[:, k])
    wo2 = mirror_directions(it2)
    back = world.accel.intersect(world.accel.spawn(p2, it2.ng, wo2, it2.offset), wo2)
    assert (back.face < 0).mean() > 0.99


def test_the_shape_moves_with_the_object(tmp_path):
    """A transform with rotation, translation and a uniform scale of 2 carries the sphere (radius 1000 mm
    in the world) with the mesh."""
    m = np.array(frame_matrix([40.0, -30.0, 20.0], [1, 0.2, 0], [0.1, -0.2, 1]))
    m[:3, :3] *= 2.0
    scene = load_scene(sphere_mirror_scene(tmp_path / "moved", transform=m.tolist()))
    world = World(scene)
    axis = m[:3, 2] / np.linalg.norm(m[:3, 2])
    centre = m[:3, 3] + 2 * R * axis
    o = m[:3, 3:4] + 600.0 * axis[:, None] + np.random.default_rng(2).uniform(-40, 40, (3, 5000))
    d = np.tile((-axis)[:, None], 5000).astype(F32)
    h, p, it = _hits(world, o, d)
    k = h.face >= 0
    assert k.mean() > 0.9
    np.testing.assert_allclose(np.linalg.norm(p[:, k] - centre[:, None], axis=0), 2 * R, rtol=0, atol=1e-8)
    assert _angle(it.ng[:, k], (centre[:, None] - p[:, k]) / (2 * R)).max() < 1e-6


def test_without_surfaces_nothing_changes(tmp_path):
    """The same mesh without a surface block traces as the mesh alone does with one, bit for bit."""
    plain = World(load_scene(sphere_mirror_scene(tmp_path / "plain", surfaces=[])))
    off = World(load_scene(sphere_mirror_scene(tmp_path / "off")), exact_surfaces=False)
    assert plain.accel.surfaces is None and off.accel.surfaces is None
    o, d = _rays(2000)
    a, b = _hits(plain, o, d), _hits(off, o, d)
    assert np.array_equal(a[0].t, b[0].t) and np.array_equal(a[2].ns, b[2].ns)
    assert np.array_equal(plain.accel.offset, off.accel.offset)
