"""hud-direct's polarised variants (presets/hud_direct_polarised.py): presets, and their primary and ghost
images by the analysis as Fresnel's equations say."""

import numpy as np
import pytest

from presets import PRESETS
from tests.support.optics import fresnel_angles
from tracer.scene import load_scene
from tracer.transport.chains import specular_paths
from tracer.transport.world import World


@pytest.mark.slow
def test_lcd_polariser_and_sunglasses_on_hud_direct(preset):
    """hud-direct's variants (presets/hud_direct_polarised.py) by the analysis: an s-polarised LCD makes the
    primary image Rs / ((Rs + Rp) / 2) = 1.85 times as bright as the unpolarised one (within the field's
    spread of incidence angles) and the ghost ratio (1 - Rs)^2; sunglasses block it; a half-wave film
    at 45 deg gives p light, (1 - Rp)^2, which they pass."""
    out = {}
    for name in ("hud-direct", "hud-direct-s", "hud-direct-s-sunglasses", "hud-direct-film-sunglasses"):
        world = World(load_scene(preset(name, resolution=(60, 20))))
        assert world.polarised
        out[name] = {}
        for p in specular_paths(world, stride=2)["paths"]:
            if np.all(np.isnan(p["lcd"])):
                continue
            # The chain's product of reflectances and transmittances, the LCD cell's modulation taken
            # out, per ray: (ray -> factor).
            out[name][p["path"]] = dict(zip(p["ray"].tolist(), (p["factor"] / p["lcd"]).tolist(), strict=True))
    prim = "windshield:reflect > mirror:reflect > lcd:transmit > scatterer:scatter"
    ghost = ("windshield:refract > windshield:reflect > windshield:refract > mirror:reflect > lcd:transmit > "
             "scatterer:scatter")
    film = lambda p: p.replace("lcd:transmit", "half_wave_film:transmit > lcd:transmit")  # noqa: E731

    def ratio(name, a, b):
        """The median over the rays that have both chains of factor(a) / factor(b)."""
        fa, fb = out[name][a], out[name].get(b, {})
        both = [r for r in fa if r in fb and fb[r] > 0]
        assert len(both) > 50, (name, a, b)
        return float(np.median([fa[r] / fb[r] for r in both]))

    rs, rp = fresnel_angles(67.0)
    unpol = ((1 - rs) ** 2 * rs + (1 - rp) ** 2 * rp) / (rs + rp)
    assert {k: round(v, 3) for k, v in {"unpol": unpol, "s": (1 - rs) ** 2, "p": (1 - rp) ** 2}.items()} == {
        "unpol": 0.576, "s": 0.545, "p": 0.958}
    # Over the view the windshield is met at 67 +- 1.5 deg, so the median ray is close to 67 deg.
    assert ratio("hud-direct", ghost, prim) == pytest.approx(unpol, rel=0.02)
    assert ratio("hud-direct-s", ghost, prim) == pytest.approx((1 - rs) ** 2, rel=0.02)
    fs = "hud-direct-film-sunglasses"
    assert ratio(fs, film(ghost), film(prim)) == pytest.approx((1 - rp) ** 2, rel=0.02)
    # An s LCD: the primary image Rs / ((Rs + Rp) / 2) as bright as with unpolarised light (the same rays).
    s_over_unpol = [out["hud-direct-s"][prim][r] / v for r, v in out["hud-direct"][prim].items()]
    assert float(np.median(s_over_unpol)) == pytest.approx(rs / (0.5 * (rs + rp)), rel=0.02)
    # Sunglasses block s light; with the film they pass p light: Rp / Rs of the s image without them.
    assert max(out["hud-direct-s-sunglasses"].get(prim, {0: 0.0}).values()) < 2e-3 * max(
        out["hud-direct-s"][prim].values())
    p_over_s = [out[fs][film(prim)][r] / v for r, v in out["hud-direct-s"][prim].items() if r in out[fs][film(prim)]]
    assert float(np.median(p_over_s)) == pytest.approx(rp / rs, rel=0.1)


def test_polarised_variants_are_presets():
    for name in ("hud-direct-s", "hud-direct-s-sunglasses", "hud-direct-film-sunglasses"):
        assert name in PRESETS
