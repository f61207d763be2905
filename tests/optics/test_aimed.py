"""The aimed mixture (tracer.optics.aimed, the paper's directed split): chi-square as a sampler at a surface
and at an emitter, and unbiased in forward renders whatever its share."""

import math

import numpy as np
import pytest

from tests.support.chi2 import SurfaceAdapter
from tests.support.optics import CHI2_TESTS, material
from tests.support.render import render
from tests.support.scenes import lcd_edge_scene
from tests.support.stats import z_bound
from tracer.optics.aimed import Aimed, CosineEmission
from tracer.optics.bsdf import IMPORTANCE


@pytest.mark.slow
@pytest.mark.parametrize("share", [0.2, 0.9])
def test_directed_split_is_unbiased(tmp_path, share):
    """The paper's directed split (one-sample mixture) gives the same answer for every share w."""
    folder = lcd_edge_scene(tmp_path / f"w{share}", share=share)
    y, var, res = render(folder, "forward", 4_000_000, seed=5)
    left = np.s_[:, :8]
    m, s = y[left].mean(), math.sqrt(var[left].sum()) / var[left].size
    assert abs(m - 500.0) < z_bound(3) * s


def test_chi2_aimed_mixture_at_a_surface_and_at_an_emitter():
    """The paper's directed split as a sampler: a Lambertian surface and a Lambertian emitter aiming
    40 % / 70 % of their samples at a disk off the normal; the mixture density is the pdf."""
    from tracer.transport.apertures import DiskTarget

    target = DiskTarget(np.array([30.0, 10.0, 60.0]), np.array([0.3, 0.1, -1.0]) / np.linalg.norm([0.3, 0.1, -1.0]),
                        12.0)
    s = material("lambertian", reflectance=0.8)
    aimed = Aimed(s, {0: (target, 0.4, "toward")}, 1)
    adapter = SurfaceAdapter(aimed, (0.2, -0.1, -1.0), (0.0, 0.0, 1.0), mode=IMPORTANCE)
    ok, msg = adapter.test(seed=41).run(0.01, CHI2_TESTS)
    assert ok, msg
    assert adapter.weight_mismatch < 1e-5  # float32 weights and densities (tracer.core.vec)
    emitter = Aimed(CosineEmission(), {0: (target, 0.7, "toward")}, 1)
    adapter = SurfaceAdapter(emitter, (0.0, 0.0, -1.0), (0.0, 0.0, 1.0), mode=IMPORTANCE)
    ok, msg = adapter.test(seed=42).run(0.01, CHI2_TESTS)
    assert ok, msg
    assert adapter.weight_mismatch < 1e-5  # float32 weights and densities (tracer.core.vec)
