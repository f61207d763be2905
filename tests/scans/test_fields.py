"""The fields a sweep sets (tracer.scans.fields) and the report keys it reads: their units, from the scene
format and the report's names."""


def test_the_axes_units_come_from_the_scene_format_and_the_reports_names():
    from tracer.products.report import report_unit
    from tracer.scans.fields import field_unit, parse_field

    assert field_unit(parse_field("objects[led_?].emission.luminance")) == "cd/m^2"
    assert field_unit(parse_field("objects[panel].emission.flux")) == "lm"
    assert field_unit(parse_field("eye.position[2]")) == field_unit(parse_field("eye.pupil_diameter_mm")) == "mm"
    assert field_unit(parse_field("environment.sun.illuminance_lux")) == "lx"
    assert field_unit(parse_field("objects[windshield].transform.rotate_deg[0]")) == "deg"
    assert field_unit(parse_field("methods.photon.radius_mm")) == "mm"
    assert field_unit(parse_field("methods.backward.max_depth")) == ""
    assert [report_unit(k) for k in ("hud.symbol_cd_m2", "luminance.max", "adaptation_luminance",
                                     "hud.spot.half_peak_diameter_deg", "seconds", "hud.contrast_ratio",
                                     "efficiency")] == ["cd/m^2"] * 3 + ["deg", "s", "1", "1"]
