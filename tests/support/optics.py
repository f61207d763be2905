"""Closed forms of optics the tests compare against, independent of tracer.optics (Fresnel's equations in
their angle form, a flat plate's incoherent reflectance), rays arriving at a surface, and a square of any
material for the samplers' tests."""

import math

import numpy as np

from tracer.core.schema import parse_block
from tracer.core.validate import FieldChecker
from tracer.optics.materials import MATERIALS
from tracer.scene import Material, SceneObject

#: The index of the glass of the windshield-like plates.
N_GLASS = 1.52


def fresnel_angles(theta_deg: float, n: float = N_GLASS) -> tuple[float, float]:
    """(R_s, R_p) from the angle form of Fresnel's equations (independent of tracer.optics)."""
    i = math.radians(theta_deg)
    t = math.asin(math.sin(i) / n)
    return math.sin(i - t) ** 2 / math.sin(i + t) ** 2, math.tan(i - t) ** 2 / math.tan(i + t) ** 2


def plate_total(r: float) -> float:
    """A flat plate's reflectance with all its internal reflections (incoherent): R + T^2 R / (1 - R^2)."""
    return r + (1 - r) ** 2 * r / (1 - r * r)


def incoming(theta_deg, n=200_000, from_front=True):
    """``n`` ray directions as rows (n, 3), in the x-z plane at ``theta_deg`` from the normal +z, onto
    the front of the plane z = 0 (or from behind it)."""
    t = np.radians(theta_deg)
    d = np.array([np.sin(t), 0.0, -np.cos(t) if from_front else np.cos(t)])
    return np.tile(d, (n, 1))


#: Sidak family of the chi-square tests of the materials' samplers and the aimed mixture.
CHI2_TESTS = 7


def obj(mtype, slot=0, aim=None, **spec):
    """A 2 x 2 mm square (normal +z) of material ``mtype`` whose fields are given as in scene.json."""
    v = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    f = np.array([[0, 1, 2], [0, 2, 3]])
    params = parse_block(FieldChecker("test"), spec, "material", MATERIALS[mtype].schema.fields)
    return SceneObject("s", slot, v, f, Material(mtype, params, aim))


def material(mtype, **spec):
    return MATERIALS[mtype]([obj(mtype, **spec)])
