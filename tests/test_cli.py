"""The command line: renders, reports, failure behaviour and bad input (file and field named,
exit status 2, no partial output)."""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, edit_json, render

from tracer.core.imageio import read_exr_channels
from tracer.scene import MESH_SUFFIXES


def hud_trace(*args):
    return subprocess.run([sys.executable, "-m", "tracer.cli", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


def test_presets_listed_and_exported(tmp_path):
    out = hud_trace("presets")
    assert out.returncode == 0
    names = [line.split()[0] for line in out.stdout.splitlines()]
    assert names == ["hud-direct", "hud-screen", "hud-screen-ideal-lcd", "hud-direct-condenser", "hud-screen-day",
                     "hud-screen-night", "hud-direct-env", "hud-direct-s", "hud-direct-s-sunglasses",
                     "hud-direct-film-sunglasses", "analytic-mirror", "analytic-disk", "analytic-furnace"]
    lines = out.stdout.splitlines()
    columns = {len(line) - len(line[len(name):].lstrip()) for name, line in zip(names, lines, strict=True)}
    assert len(columns) == 1, "every summary starts in one column"
    for name in ("hud-direct", "hud-screen", "hud-direct-condenser"):
        assert hud_trace("export", name, tmp_path / name).returncode == 0
        assert (tmp_path / name / "scene.json").is_file() and (tmp_path / name / "textures" / "slide.png").is_file()


def test_render_hud_direct_writes_image_preview_report(tmp_path):
    """Backward tracing: forward tracing's symbols at 3 M rays are a sum of few heavy particles (40 %
    error), whose batch-means error is no bound to test against (test_transport.py compares the methods
    with the statistics that fit them)."""
    out = tmp_path / "o"
    res = hud_trace("render", "hud-direct", "--method", "backward", "--rays", 3_000_000, "--seed", 7, "--out", out)
    assert res.returncode == 0, res.stderr
    report = json.loads((out / "report.json").read_text())
    for key in ("method", "seed", "rays", "paths", "seconds", "rays_per_second", "efficiency", "luminance",
                "adaptation_luminance", "warnings"):
        assert key in report
    assert report["rays"] >= 3_000_000 and 0 < report["efficiency"] < 1
    assert set(report["luminance"]) >= {"mean", "max", "log_average"}
    ch, attrs = read_exr_channels(out / "image.exr")
    assert set(ch) == {"R", "G", "B", "Y", "Y_var"}
    y = 0.2126 * ch["R"] + 0.7152 * ch["G"] + 0.0722 * ch["B"]
    np.testing.assert_allclose(ch["Y"], y, rtol=1e-5, atol=1e-6)
    assert all(np.all(np.isfinite(c)) for c in ch.values())
    assert attrs["hud:method"] == "backward" and attrs["hud:seed"] == "7"
    bt = report["brightness_theorem"]
    # The symbols follow the brightness theorem; the black leak is symbol / 300 (plus ghost spill).
    assert bt["symbol"]["predicted_cd_m2"] > 0
    sym = bt["symbol"]
    assert abs(sym["rendered_cd_m2"] - sym["predicted_cd_m2"]) < 4.5 * math.hypot(
        sym["standard_error_cd_m2"], sym["predicted_standard_error_cd_m2"])
    assert "ghost" in bt and bt["ghost"]["ratio_to_symbol"] > 0.3
    assert (out / "preview.png").is_file()


def test_same_seed_same_image_and_seeds_differ_by_their_variance(preset):
    folder = preset("analytic-mirror", resolution=(16, 12))
    y1, v1, _ = render(folder, "forward", 600_000, seed=11)
    y2, _, _ = render(folder, "forward", 600_000, seed=11)
    y3, v3, _ = render(folder, "forward", 600_000, seed=12)
    assert np.array_equal(y1, y2)
    lit = (v1 > 0) & (v3 > 0)
    z = (y1 - y3)[lit] / np.sqrt(v1 + v3)[lit]
    assert not np.array_equal(y1, y3)
    assert abs(z.mean()) < 4 / math.sqrt(lit.sum()) and 0.7 < z.std() < 1.3


@pytest.mark.parametrize("case", ["dark scene", "light out of reach"])
def test_no_light_is_reported_not_silent(tmp_path, preset, case):
    """A black image is never silent, and the message says why: a scene without light is dark; light
    the method does not find is the method's failure or no light reaching the eye (issue 9, finding 18:
    the two messages contradicted each other)."""
    folder = preset("analytic-mirror")
    if case == "dark scene":
        edit_json(folder, lambda d: d["objects"][2]["emission"].update(luminance=0.0))
        expected, absent = "the scene has no light source", "no light path found"
    else:  # the panel turned over (its local y and z negated): it emits downward, away from the mirror
        def flip(d):
            m = d["objects"][2]["transform"]["matrix"]
            for row in m[:3]:
                row[1], row[2] = -row[1], -row[2]
        edit_json(folder, flip)
        expected, absent = "no light path found", "the scene has no light source"
    out = tmp_path / "o"
    res = hud_trace("render", folder, "--method", "backward", "--rays", 200_000, "--out", out, "--quiet")
    assert res.returncode == 3
    assert expected in res.stderr and absent not in res.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["efficiency"] == 0 and any(expected in w for w in report["warnings"])
    ch, _ = read_exr_channels(out / "image.exr")
    assert all(np.all(np.isfinite(c)) for c in ch.values())


BAD = {
    "malformed_json": (lambda p: (p / "scene.json").write_text("{ not json"), ""),
    "missing_mesh": (lambda p: edit_json(p, lambda d: d["objects"][0].update(mesh="meshes/nope.obj")),
                     "objects[0].mesh"),
    "missing_texture": (lambda p: edit_json(p, lambda d: d["objects"][2]["material"].update(image="textures/nope.png")),
                        "objects[2].material.image"),
    "negative_luminance": (lambda p: edit_json(p, lambda d: d["objects"][-2]["emission"].update(luminance=-5)),
                           "emission.luminance"),
    "zero_pupil": (lambda p: edit_json(p, lambda d: d["eye"].update(pupil_diameter_mm=0)), "eye.pupil_diameter_mm"),
    "negative_pupil": (lambda p: edit_json(p, lambda d: d["eye"].update(pupil_diameter_mm=-4)),
                       "eye.pupil_diameter_mm"),
    "unknown_material": (lambda p: edit_json(p, lambda d: d["objects"][1]["material"].update(type="unobtainium")),
                         "objects[1].material.type"),
    "degenerate_transform": (lambda p: edit_json(p, lambda d: d["objects"][1].update(
        transform={"scale": [1, 0, 1]})), "objects[1].transform"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_names_file_and_field_and_writes_nothing(tmp_path, case):
    folder = tmp_path / "scene"
    assert hud_trace("export", "hud-direct", folder).returncode == 0
    spoil, field = BAD[case]
    spoil(folder)
    out = tmp_path / "out"
    res = hud_trace("render", folder, "--method", "forward", "--rays", 1000, "--out", out, "--quiet")
    assert res.returncode == 2, res.stderr
    assert "scene.json" in res.stderr and field in res.stderr
    assert "Traceback" not in res.stderr
    assert not out.exists()


def test_ctrl_c_writes_a_partial_result(tmp_path):
    import signal
    import time

    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-m", "tracer.cli", "render", "analytic-mirror", "--method", "forward",
                             "--seconds", "120", "--out", str(out)], cwd=ROOT, stderr=subprocess.PIPE, text=True)
    time.sleep(6)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    report = json.loads((out / "report.json").read_text())
    assert report["partial"] is True and report["seconds"] < 60 and report["rays"] > 0
    ch, attrs = read_exr_channels(out / "image.exr")
    assert attrs["hud:partial"] == 1 and all(np.all(np.isfinite(c)) for c in ch.values())


@pytest.mark.parametrize("ext", [s.removeprefix(".") for s in MESH_SUFFIXES if s != ".obj"])
def test_meshes_load_from_every_format_the_scene_format_names(preset, ext):
    """The mirror of analytic-mirror, re-saved as PLY, STL, OFF, GLB or glTF (tracer.scene.MESH_SUFFIXES
    but OBJ, the presets' own), renders the same closed-form value."""
    import trimesh

    from tracer.scene import load_scene

    folder = preset("analytic-mirror", resolution=(8, 6))
    src = load_scene(folder).object("mirror")
    m = json.loads((folder / "scene.json").read_text())
    world = trimesh.Trimesh(src.vertices, src.faces, process=False)
    world.export(folder / f"meshes/mirror.{ext}")
    m["objects"][0]["mesh"] = f"meshes/mirror.{ext}"
    m["objects"][0].pop("transform")
    (folder / "scene.json").write_text(json.dumps(m))
    loaded = load_scene(folder).object("mirror")
    np.testing.assert_allclose(np.sort(loaded.triangles.reshape(-1, 3), axis=0),
                               np.sort(src.triangles.reshape(-1, 3), axis=0), atol=1e-4)
    y, var, _ = render(folder, "backward", 300_000)
    assert y.max() == pytest.approx(850.0, rel=0.01)


@pytest.mark.parametrize("method", ["forward", "backward"])
def test_two_processes_give_the_same_image_as_one(preset, method):
    """Seed-addressed batches merged in order: the same film on one and on two processes (to the
    last bits of rounding)."""
    from conftest import films_match

    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime.parallel import render_parallel
    from tracer.scene import load_scene

    folder = preset("hud-direct")
    one = INTEGRATORS[method](load_scene(folder), 9).render(Budget(rays=2_500_000))
    two = render_parallel(INTEGRATORS[method](load_scene(folder), 9), Budget(rays=2_500_000), workers=2)
    assert one.batches == two.batches and one.rays == two.rays and one.found == two.found
    assert films_match(one, two)


def test_dask_cluster_gives_the_same_image(preset):
    """The same seed-addressed batches on a Dask LocalCluster merge to the local image."""
    distributed = pytest.importorskip("distributed")
    from conftest import films_match

    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime.distributed import render_dask
    from tracer.scene import load_scene

    folder = preset("hud-direct")
    one = INTEGRATORS["forward"](load_scene(folder), 4).render(Budget(rays=2_000_000))
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    with cluster, distributed.Client(cluster) as client:
        dask = render_dask(INTEGRATORS["forward"](load_scene(folder), 4), Budget(rays=2_000_000), client)
    assert dask.batches == one.batches and films_match(one, dask)


def test_workers_start_when_the_tracer_is_a_subpackage_of_made_up_packages(preset, tmp_path):
    """Inside Blender the tracer is bl_ext.<repository>.hud_tracer.tracer, under packages Blender makes
    up at run time, which a plain interpreter cannot import. Here a copy of the tracer is imported the
    same way (an empty package "hud_made_up" over a folder that links to this checkout): its workers
    start, and the image equals the one-process render of the ordinary tracer. Its main module is
    hidden from the workers (this test process's own would be pytest's)."""
    import importlib
    import types

    from conftest import films_match

    from tracer.methods import INTEGRATORS, Budget
    from tracer.scene import load_scene

    repo = tmp_path / "repo"
    repo.mkdir()
    (repo / "hud_tracer").symlink_to(ROOT, target_is_directory=True)
    made_up = types.ModuleType("hud_made_up")
    made_up.__path__ = [str(repo)]
    sys.modules["hud_made_up"] = made_up
    try:
        parallel = importlib.import_module("hud_made_up.hud_tracer.tracer.runtime.parallel")
        integrators = importlib.import_module("hud_made_up.hud_tracer.tracer.methods")
        scene_mod = importlib.import_module("hud_made_up.hud_tracer.tracer.scene")
        assert parallel._made_up_packages() == [("hud_made_up", [str(repo)])]
        folder = preset("analytic-mirror")
        previews = []
        two = parallel.render_parallel(integrators.INTEGRATORS["backward"](scene_mod.load_scene(folder), 5),
                                       integrators.Budget(rays=800_000), workers=2,
                                       preview=lambda film: previews.append(film.replicates))
        assert type(two).__module__ == "hud_made_up.hud_tracer.tracer.methods.base"
    finally:
        for name in [n for n in sys.modules if n == "hud_made_up" or n.startswith("hud_made_up.")]:
            del sys.modules[name]
    one = INTEGRATORS["backward"](load_scene(folder), 5).render(Budget(rays=800_000))
    assert one.batches == two.batches > 1 and films_match(one, two)
    # The preview saw the film while it grew (at most once a second: at least the first merge).
    assert previews and previews == sorted(previews) and previews[-1] < two.film.replicates


def test_a_worker_that_cannot_start_stops_the_render_with_its_message(preset, tmp_path):
    """A worker whose world cannot be built (its scene folder is gone) says why, and the render stops
    with that message instead of waiting for workers that the pool would start again and again."""
    import shutil
    import time

    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime.parallel import render_parallel
    from tracer.scene import load_scene

    folder = preset("analytic-mirror")
    integrator = INTEGRATORS["backward"](load_scene(folder), 1)
    shutil.rmtree(folder)
    t0 = time.perf_counter()
    with pytest.raises(RuntimeError, match="could not start: SceneError: .*scene.json: scene file not found"):
        render_parallel(integrator, Budget(rays=100_000), workers=2)
    assert time.perf_counter() - t0 < 60


def test_readouts_prints_the_reports_figures(tmp_path):
    """hud-trace readouts DIR prints one row per figure of the report (the add-on's HUD Readouts); a file
    that is not a report gives one line and exit 2."""
    from tracer.cli import main
    from tracer.products.report import readouts

    out = tmp_path / "r"
    assert main(["render", "analytic-mirror", "--rays", "300000", "--seed", "2", "--out", str(out), "--quiet"]) == 0
    proc = subprocess.run([sys.executable, "-m", "tracer.cli", "readouts", str(out)], capture_output=True, text=True,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    rows = readouts(json.loads((out / "report.json").read_text()))
    lines = proc.stdout.splitlines()
    assert len(lines) == len(rows) and all(line.split()[0] == label.split()[0] and line.endswith(text)
                                           for line, (label, text) in zip(lines, rows, strict=True))
    (tmp_path / "x.json").write_text("{}")
    bad = subprocess.run([sys.executable, "-m", "tracer.cli", "readouts", str(tmp_path / "x.json")],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "not a hud-trace report" in bad.stderr


def test_workers_refuse_a_scene_folder_that_changed_since_the_render_began(preset):
    """Workers load the scene from its folder: one edited after the render began (here in the parent's
    memory, as a script might) would render another scene in them; the render stops and says so."""
    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime.parallel import render_parallel
    from tracer.scene import load_scene

    folder = preset("analytic-mirror")
    integrator = INTEGRATORS["backward"](load_scene(folder), 1)
    edit_json(folder, lambda d: d["eye"].update(pupil_diameter_mm=3.0))
    with pytest.raises(RuntimeError, match="another scene than the one the render began with"):
        render_parallel(integrator, Budget(rays=100_000), workers=2)


def test_external_files_are_allowed_in_the_workers_too(preset, tmp_path):
    """--allow-external-files with two workers: the workers load the folder with the same rule."""
    from tracer.cli import main

    folder = preset("analytic-mirror")
    outside = tmp_path / "meshes-outside"
    (folder / "meshes").rename(outside)
    edit_json(folder, lambda d: [o.update(mesh=str(outside / Path(o["mesh"]).name)) for o in d["objects"]])
    assert main(["render", str(folder), "--rays", "200000", "--workers", "2", "--out", str(tmp_path / "o"),
                 "--quiet", "--allow-external-files"]) == 0


@pytest.mark.parametrize("text,value", [("5000000", 5_000_000), ("5e6", 5_000_000), ("5_000_000", 5_000_000),
                                        ("2.5e5", 250_000), ("2.5e-5", None), ("1.5", None), ("inf", None),
                                        ("nan", None), ("lots", None)])
def test_a_ray_budget_may_be_written_as_a_whole_number_in_any_notation(text, value):
    """--rays 5e6 was "invalid int value" although 1e8 is how the README and the benchmarks write it."""
    import argparse

    from tracer.cli import ray_count

    if value is None:
        with pytest.raises(argparse.ArgumentTypeError, match="number of rays"):
            ray_count(text)
    else:
        assert ray_count(text) == value and isinstance(ray_count(text), int)


@pytest.mark.parametrize("args,words", [
    (("render", "hud-direct", "--secs", "3", "--out", "o"), "unrecognized arguments: --secs"),
    (("sweep", "hud-direct", "--sets", "x=1:2:2", "--rays", "1000", "--out", "o"), "unrecognized arguments: --sets"),
    (("render", "hud-direct", "--sec", "3"), "the following arguments are required: --out"),  # an abbreviation
])
def test_a_misspelt_option_is_named_before_a_missing_required_one(args, words, tmp_path):
    """argparse checks required options before unknown ones: `render --secs 3` said only that --rays or
    --seconds is required, which sends the user looking for the wrong mistake."""
    res = subprocess.run([sys.executable, "-m", "tracer.cli", *args], cwd=tmp_path, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and words in res.stderr, res.stderr
    assert not (tmp_path / "o").exists()
