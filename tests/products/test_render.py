"""Rendering a scene into its outputs (tracer/products/render.py): the pupil follows the adaptation
luminance of the image."""

from __future__ import annotations

import pytest

from tests.support.scenes import LOW, edit_json, sky
from tracer.core.units import luminance
from tracer.methods import Budget
from tracer.optics.pupil import pupil_diameter_mm
from tracer.products.tonemap import adaptation_luminance
from tracer.scene import load_scene

pytestmark = pytest.mark.slow


def test_the_pupil_follows_the_adaptation_luminance_of_the_image(preset):
    """eye "pupil_diameter_mm": "auto" with "adaptation_luminance_cd_m2": "image": a pilot finds the
    adaptation luminance (here the mean) of what the eye sees and Watson & Yellott's formula gives the
    pupil; the report says both, and they agree with the final image's own adaptation luminance."""
    from tracer.products.render import render_scene

    folder = preset("hud-direct", resolution=LOW)
    sky(folder, 3000.0)
    edit_json(folder, lambda d: d["eye"].update(pupil_diameter_mm="auto", adaptation_luminance_cd_m2="image",
                                                adaptation="mean", observer_age=40))
    report, result = render_scene(load_scene(folder), "backward", Budget(rays=3_000_000), 1, folder.parent / "out")
    pupil = result.extra["pupil"]
    final = adaptation_luminance(luminance(result.film.rgb()), "mean")
    assert report["adaptation_mode"] == "mean" and report["adaptation_luminance"] == pytest.approx(final)
    assert pupil["pilot_adaptation_luminance_cd_m2"] == pytest.approx(final, rel=0.05)
    assert pupil["pupil_diameter_mm"] == pytest.approx(pupil_diameter_mm(pupil["pilot_adaptation_luminance_cd_m2"],
                                                                         age_years=40), rel=1e-12)
    # The first guess was the sky's 3000 cd/m^2; the eye sees the sky through the windshield, and the HUD.
    assert pupil["first_guess_pupil_diameter_mm"] == pytest.approx(pupil_diameter_mm(3000.0, age_years=40))
