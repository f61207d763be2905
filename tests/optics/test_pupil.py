"""The eye's pupil from the adaptation luminance (tracer.optics.pupil, Watson & Yellott), and an automatic
pupil that follows the environment."""

import pytest

from tests.support.scenes import edit_json


@pytest.mark.parametrize("luminance,expected", [(1.0, 5.12), (292.0, 2.61), (3000.0, 2.25), (21013.0, 2.12)])
def test_pupil_from_adaptation_watson_yellott(luminance, expected):
    """The derived values of hud-physics.md (60 deg field, age 30, both eyes)."""
    from tracer.optics.pupil import pupil_diameter_mm

    assert pupil_diameter_mm(luminance) == pytest.approx(expected, abs=0.006)


def test_auto_pupil_follows_the_environment(preset):
    from tracer.optics.pupil import pupil_diameter_mm
    from tracer.scene import load_scene

    folder = preset("analytic-furnace")
    edit_json(folder, lambda d: (d.update(environment={"type": "uniform", "luminance": 292.0}),
                                 d["eye"].update(pupil_diameter_mm="auto")))
    assert load_scene(folder).eye.pupil_diameter_mm == pytest.approx(pupil_diameter_mm(292.0))
    edit_json(folder, lambda d: d["eye"].update(adaptation_luminance_cd_m2=3000.0, observer_age=60))
    assert load_scene(folder).eye.pupil_diameter_mm == pytest.approx(pupil_diameter_mm(3000.0, age_years=60))
