"""``hud-trace optics`` and the optical analysis on the command line (tracer/cli.py): its output set and
what it prints, its exit statuses, requirements refused before any ray (also by a render and a sweep),
and a sweep of the analysis alone."""

import json

import pytest

from tests.support import imaging
from tests.support.cli import assert_one_line_error, hashes, run_cli
from tests.support.scenes import edit_json
from tracer.products.optics import OUTPUT_NAMES, read_csv


def test_optics_writes_its_set_and_prints_the_figures(tmp_path):
    folder = imaging.plane_mirror(tmp_path / "p", target={"distance_mm": 1000.0, "eye_grid": [3, 3],
                                                          "requirements": ["design_eye.vid_mm < 1001",
                                                                           "eyebox.dipvergence_mrad <= 0.01"]})
    code, err = run_cli("optics", folder, "--out", tmp_path / "o")
    assert code == 0, err
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == sorted(OUTPUT_NAMES)
    assert "VID: 1000.0 mm" in err and "requirement" in err.lower()
    doc = json.loads((tmp_path / "o" / "optics.json").read_text())
    assert doc["requirements_met"] and [r["met"] for r in doc["requirements"]] == [True, True]
    assert doc["definitions"]["vid_mm"]["unit"] == "mm"
    rows = read_csv(tmp_path / "o" / "optics.csv")
    assert len(rows) == 15 + 9 * 15  # the design eye point's field points, then every eye point's
    design = [r for r in rows if r["eye"] == "design"]
    assert [r["vid_mm"] for r in design] == pytest.approx([f["vid_mm"] for f in doc["field_points"]], rel=1e-12)


def test_a_requirement_not_met_exits_3_with_the_set_written(tmp_path):
    folder = imaging.plane_mirror(tmp_path / "p", target={"eye_grid": [1, 1],
                                                          "requirements": ["design_eye.vid_mm > 2000"]})
    code, err = run_cli("optics", folder, "--out", tmp_path / "o", "--no-mesh-comparison")
    assert code == 3, err
    assert "NOT met" in err
    assert not json.loads((tmp_path / "o" / "optics.json").read_text())["requirements_met"]


@pytest.mark.parametrize("args, words", [
    (["--field-grid", "1", "3"], ["--field-grid", "[2, 41]"]),
    (["--eye-grid", "0", "3"], ["--eye-grid", "[1, 41]"]),
])
def test_bad_grids_give_one_line(tmp_path, args, words):
    folder = imaging.plane_mirror(tmp_path / "p")
    code, err = run_cli("optics", folder, "--out", tmp_path / "o", *args)
    assert_one_line_error(code, err, *words)
    assert not (tmp_path / "o").exists()


def test_a_mistyped_requirement_is_refused_by_optics_render_and_sweep_before_any_ray(tmp_path):
    folder = imaging.plane_mirror(tmp_path / "p", target={"requirements": ["design_eye.vid < 1001"]})
    for args in (["optics", folder, "--out", tmp_path / "o"],
                 ["render", folder, "--rays", "1e12", "--out", tmp_path / "o"]):  # a late refusal would hang
        code, err = run_cli(*args)
        assert_one_line_error(code, err, "scene.json", "target.requirements[0]", "vid_mm")
        assert not (tmp_path / "o").exists()
    code, err = run_cli("sweep", imaging.plane_mirror(tmp_path / "q"), "--optics", "--set",
                        "objects[panel].emission.luminance=1:2:2", "--require",
                        "optics.design_eye.ghost_seperation_arcmin < 1", "--out", tmp_path / "s")
    assert_one_line_error(code, err, "--require", "ghost_separation_arcmin")


def test_no_eyebox_refuses_a_requirement_on_the_eyebox(tmp_path):
    folder = imaging.plane_mirror(tmp_path / "p", target={"requirements": ["eyebox.dipvergence_mrad < 1"]})
    (tmp_path / "o").mkdir()
    before = hashes(tmp_path / "o")
    code, err = run_cli("optics", folder, "--out", tmp_path / "o", "--no-eyebox")
    assert_one_line_error(code, err, "target.requirements[0]", "--no-eyebox")
    assert hashes(tmp_path / "o") == before


def test_a_sweep_of_the_analysis_finds_the_mirror_distance(tmp_path):
    """The panel moved along the fold: VID = 400 + the panel's distance, a requirement's window found by
    the sweep's interpolation without a render."""
    folder = imaging.plane_mirror(tmp_path / "p", target={"eye_grid": [1, 1]})
    code, err = run_cli("sweep", folder, "--optics", "--set", "objects[panel].transform.matrix[2][3]=500:700:5",
                        "--require", "optics.design_eye.vid_mm <= 1050", "--out", tmp_path / "s")
    assert code == 0, err
    summary = json.loads((tmp_path / "s" / "sweep.json").read_text())
    assert summary["method"] == "optics"
    (interval,) = summary["recommendation"]["intervals"]
    assert interval["to"] == pytest.approx(650.0, abs=0.5)  # 400 + 650 = 1050 mm
    for k in range(5):
        assert (tmp_path / "s" / "runs" / str(k) / "optics.json").is_file()


def test_the_target_block_shapes_the_optics_of_a_render(tmp_path):
    """report.json's optics block: the same summary as hud-trace optics (no spots), warnings included."""
    folder = imaging.plane_mirror(tmp_path / "p", target={"eye_grid": [3, 1]})
    edit_json(folder, lambda d: d["eye"].update(resolution=[24, 16]))
    code, err = run_cli("render", folder, "--rays", "100000", "--workers", "1", "--quiet", "--out", tmp_path / "r")
    assert code == 0, err
    block = json.loads((tmp_path / "r" / "report.json").read_text())["optics"]
    assert block["design_eye"]["vid_mm"] == pytest.approx(1000.0, rel=1e-3)
    assert block["target"]["eye_grid"] == [3, 1] and block["warnings"] == []
