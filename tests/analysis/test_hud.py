"""The HUD figures' symbols and background on a screen HUD (tracer.analysis.sections, tracer.analysis.hud):
where the eye sees the LCD only through a diffuse screen, the photon map's photons carry the LCD cell they
crossed, so the symbol and background pixels come from where each cell's image falls on the screen, not
from the rendered values (a threshold on a noisy image read symbols 10 times too bright)."""

import numpy as np
import pytest

from tests.support.addon import read_multilayer
from tests.support.scenes import lcd_screen_scene
from tests.support.stats import z_bound
from tracer.methods import Budget
from tracer.products.render import render_scene
from tracer.scene import load_scene

#: lcd_screen_scene's LCD contrast ratio.
CR = 100.0


@pytest.mark.slow
def test_a_screen_hud_takes_its_symbols_from_the_lcd_cells_its_photons_crossed(tmp_path):
    """An LCD whose left half is clear lies 0.5 mm behind a diffuse screen: the symbol pixels are the
    screen's left half and the background its right half (away from the edge), for a backward and a
    photon render alike (the same pixels: they come from the photons, whatever the image's noise). The
    symbol and background luminances stand in the LCD's contrast ratio (the backlight is symmetric about
    the edge), and each section agrees with the brightness-theorem prediction within both errors."""
    folder = lcd_screen_scene(tmp_path / "s", contrast=CR)
    masks = {}
    for method in ("backward", "photon"):
        out = tmp_path / method
        report, _ = render_scene(load_scene(folder), method, Budget(rays=400_000), 1, out)
        hud, bt = report["hud"], report["brightness_theorem"]
        assert hud["symbol_pixels_from"] == "lcd_cells_via_photons", hud
        assert abs(hud["symbol_cd_m2"] / hud["background_cd_m2"] / CR - 1) < 0.1, hud
        assert bt["valid"] and bt["photon_map"] is not None, bt["not_comparable"]
        for key in ("symbol", "background"):
            assert abs(bt[key]["rendered_minus_predicted_sigma"]) < z_bound(4), (method, key, bt[key])
        y = read_multilayer(out / "image.exr")["Y"]
        width = y.shape[1]
        # The image's left half is the clear half (the eye looks along +y with z up: x to the right).
        assert y[:, : width // 2 - 2].mean() > 50 * y[:, width // 2 + 2:].mean()
        masks[method] = (hud["symbol_pixels"], hud["background_pixels"])
        assert hud["symbol_pixels"] > 0.3 * y.size and hud["background_pixels"] > 0.1 * y.size, hud
    assert masks["backward"] == masks["photon"]


def test_the_symbols_lie_on_the_clear_half_and_the_background_on_the_black_half(tmp_path):
    """The sections themselves, pixel by pixel: every symbol pixel's chief ray lands on the clear half's
    image and every background pixel's on the black half's, at least the background margin away."""
    from tracer.analysis.brightness import analysis_photon_map
    from tracer.analysis.sections import find_sections
    from tracer.transport.chains import specular_paths
    from tracer.transport.world import World

    world = World(load_scene(lcd_screen_scene(tmp_path / "s", contrast=CR)))
    chains = specular_paths(world, environment=False)
    pmap = analysis_photon_map(world, chains, seed=2)
    assert pmap is not None and pmap.lcd is not None
    sections = find_sections(world, chains, photons=pmap)
    assert sections.symbols_from == "lcd_cells_via_photons"
    shape = (world.eye.height, world.eye.width)
    sym = sections.pixels(sections.masks["symbol"], shape)
    bg = sections.pixels(sections.masks["background"], shape)
    cols = np.arange(shape[1])[None, :].repeat(shape[0], axis=0)
    middle = shape[1] / 2
    assert sym.any() and bg.any()
    assert cols[sym].max() < middle and cols[bg].min() >= middle + 1, (cols[sym].max(), cols[bg].min())
    assert not find_sections(world, chains).symbols_from  # without photons: the luminance threshold's turn
