"""hud-direct's optics (presets/hud_direct.py, presets/hud_direct_optics.py) through the optical
analysis: the exact ellipsoid mirror, the wedge that fuses the ghost, the curved windshield refocused."""

import math

import pytest

from presets import PRESETS, hud_direct
from presets.hud_direct_optics import WEDGE_MRAD, first_order_wedge_mrad
from tracer.analysis.optics import analyse
from tracer.scene import load_scene


@pytest.fixture(scope="module")
def optics(tmp_path_factory):
    cache = {}

    def run(name, **kw):
        if name not in cache:
            folder = PRESETS[name].write(tmp_path_factory.mktemp(name) / name)
            cache[name] = analyse(load_scene(folder), **kw)
        return cache[name]

    return run


def test_hud_direct_images_the_lcd_where_it_was_designed(optics):
    """VID 2500 mm, look-down 4 deg, 6 x 2 deg (the design's paraxial layout, presets/hud_direct.py), and
    the mirror's exact ellipsoid against its 160 x 110 cell mesh stated for every metric."""
    doc = optics("hud-direct")
    s = doc["summary"]["design_eye"]
    assert doc["chains"] == {"pgu": "lcd", "primary": "windshield:reflect > mirror:reflect > lcd",
                             "ghost": "windshield:refract > windshield:reflect > windshield:refract > "
                                      "mirror:reflect > lcd"}
    assert s["vid_mm"] == pytest.approx(hud_direct.VID, rel=0.001)
    assert s["look_down_deg"] == pytest.approx(hud_direct.LOOK_DOWN_DEG, abs=0.01)
    assert s["fov_h_deg"] == pytest.approx(6.0, rel=0.02) and s["fov_v_deg"] == pytest.approx(2.0, rel=0.02)
    assert doc["exact_surfaces"] == ["mirror"]
    cmp = doc["mesh_comparison"]["design_eye"]
    assert set(cmp) >= {"vid_mm", "astigmatism_d", "static_distortion_mrad", "ghost_separation_arcmin"}
    for v in cmp.values():
        assert v["error"] == pytest.approx(v["mesh"] - v["exact"])
    # the flat plate's ghost, d / VID to first order: 2 t tan(theta') cos(theta) magnified by nothing at the eye
    theta = math.radians(hud_direct.design()["incidence_windshield_deg"])
    tp = math.asin(math.sin(theta) / 1.52)
    d = 2 * hud_direct.GLASS_MM * math.tan(tp) * math.cos(theta)
    assert s["ghost_separation_centre_arcmin"] == pytest.approx(d / hud_direct.VID * 180 * 60 / math.pi, rel=0.05)


def test_the_wedge_fuses_the_ghost_at_the_design_eye_point(optics):
    """Below 0.1 arcmin; the wedge is the first-order estimate times VID / (VID - a), a the eye's
    distance to the windshield (the reference's formula sets the deviation at the glass to d / VID;
    seen from the eye at a point VID away it moves the ghost by (VID - a) / VID of it)."""
    s = optics("hud-direct-wedge")["summary"]["design_eye"]
    assert s["ghost_separation_centre_arcmin"] < 0.1
    flat = optics("hud-direct")["summary"]["design_eye"]
    assert s["ghost_separation_arcmin"] < 0.25 * flat["ghost_separation_arcmin"]
    factor = hud_direct.VID / (hud_direct.VID - hud_direct.EYE_TO_WINDSHIELD)
    assert WEDGE_MRAD == pytest.approx(first_order_wedge_mrad() * factor, rel=0.02)


def test_the_wedge_leaves_the_primary_image_alone(optics):
    flat, wedge = (optics(n)["summary"] for n in ("hud-direct", "hud-direct-wedge"))
    for key in ("vid_mm", "static_distortion_mrad", "fov_h_deg"):
        assert wedge["design_eye"][key] == pytest.approx(flat["design_eye"][key], rel=1e-3)
    assert wedge["eyebox"]["dipvergence_mrad"] == pytest.approx(flat["eyebox"]["dipvergence_mrad"], rel=1e-3)


def test_the_curved_windshield_is_refocused_and_shows_what_it_costs(optics):
    """The LCD moved for the mean power: the VID within 1 % of the design's, but astigmatism (its two
    sections' powers differ at 63 deg) and a binocular disparity the flat windshield lacks."""
    flat, curved = optics("hud-direct"), optics("hud-direct-curved")
    s = curved["summary"]["design_eye"]
    assert s["vid_mm"] == pytest.approx(hud_direct.VID, rel=0.01)
    assert s["astigmatism_centre_d"] > 0.03 > 10 * flat["summary"]["design_eye"]["astigmatism_centre_d"]
    assert curved["exact_surfaces"] == ["mirror", "windshield"]
    box, flat_box = curved["summary"]["eyebox"], flat["summary"]["eyebox"]
    assert box["dipvergence_mrad"] > flat_box["dipvergence_mrad"] + 0.3
