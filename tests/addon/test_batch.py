"""``hud-render`` (hud_addon/batch.py): a saved .blend rendered headless into an output set with the
command line's report; a World image that lost its pixels, bad arguments and a file Blender cannot render
refused in one line, exit 2, nothing written.

Each scenario (a ``scenario_*`` function: the scene set up, rendered or exported inside the bpy module)
sits before the tests that assert on its result, and runs in a process of its own through
tests/addon/blender_runner.py (tests.support.addon.in_blender)."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from tests.support.addon import in_blender, needs_bpy, read_multilayer
from tests.support.paths import ROOT

pytestmark = needs_bpy


@pytest.mark.slow
def test_hud_render_renders_a_saved_blend(tmp_path):
    """The .blend comes from tools/preset_blend.py, the README's headless way to make one."""
    blend = tmp_path / "mirror.blend"
    made = subprocess.run([sys.executable, str(ROOT / "tools" / "preset_blend.py"), "analytic-mirror", str(blend)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert made.returncode == 0 and blend.is_file(), made.stderr[-3000:]
    again = subprocess.run([sys.executable, str(ROOT / "tools" / "preset_blend.py"), "analytic-mirror", str(blend)],
                           capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert again.returncode == 2 and "exists" in again.stderr and len(again.stderr.strip().splitlines()) == 1
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "hud_addon.batch", str(blend), "--out", str(out), "--rays", "600000",
                           "--method", "backward", "--seed", "2"], capture_output=True, text=True, timeout=600,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert sorted(p.name for p in out.iterdir()) == ["falsecolour.png", "image.exr", "report.json"]  # a set
    report = json.loads((out / "report.json").read_text())
    assert report["method"] == "backward" and report["rays"] >= 600_000 and report["seed"] == 2
    assert len(report["run_id"]) == 32 and report["blend"] == str(blend)
    # The command line's report: rays/s, noise, log-average, the analysis.
    assert report["rays_per_second"] > 0 and report["noise"]["median_relative_standard_error_lit_pixels"] > 0
    assert report["luminance"]["log_average"] > 0 and report["brightness_theorem"]["image"]["predicted_cd_m2"] > 0
    ch = read_multilayer(out / "image.exr")
    y = ch["ViewLayer.Y.X"]
    assert np.all(np.isfinite(y)) and abs(y.max() - 850.0) < 0.02 * 850
    from tracer.core.imageio import read_image
    from tracer.products.falsecolour import false_colour

    expected, _ = false_colour(y.astype(np.float64))
    got = np.rint(read_image(out / "falsecolour.png", linear=True) * 255).astype(np.uint8)
    assert got.shape == expected.shape and np.abs(got.astype(int) - expected).max() <= 1


def scenario_save_generated_hdri(path):
    """analytic-mirror with an HDRI environment whose image is generated, filled, neither saved nor
    packed, saved into a .blend (its pixels are gone when the file is opened again)."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="analytic-mirror")
    img = bpy.data.images.new("sky", 64, 32, float_buffer=True)
    img.pixels.foreach_set([1.0] * (64 * 32 * 4))
    world = bpy.context.scene.world
    world.hud.kind, world.hud.image = "hdri", img
    warnings = sys.modules[f"{module}.hud_addon.messages"].generated_image_warnings(bpy.context.scene)
    bpy.ops.wm.save_as_mainfile(filepath=path)
    disable(module)
    return {"warnings": warnings}


@pytest.mark.slow
def test_hud_render_names_the_world_image_that_lost_its_pixels(tmp_path):
    """A .blend whose HDRI is a generated image that was never saved or packed:
    hud-render exits 2 with one line that names the World and the image (not a temporary scene.json),
    and says why its pixels are gone; nothing is written."""
    blend = tmp_path / "generated.blend"
    in_blender(scenario_save_generated_hdri, blend)
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "hud_addon.batch", str(blend), "--out", str(out), "--rays",
                           "100000"], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1, proc.stderr
    line = errors[0]
    assert "World 'World'" in line and "HDRI image 'sky'" in line and "generated image" in line and "Pack" in line
    assert "scene.json" not in line and "hud-blender-" not in line
    assert not out.exists() or list(out.iterdir()) == []


@pytest.mark.parametrize("case", ["--out is a file", "--seconds nan", "--method backwards"])
def test_hud_render_refuses_bad_arguments_before_blender_starts(tmp_path, case):
    """hud-render checks its arguments and locks its output folder first: one line, exit 2,
    and the .blend is not even opened (it does not exist here: the refusal comes before). A misspelt
    method was Blender's enum traceback."""
    out = tmp_path / "out"
    args = ["--rays", "1000"]
    if case == "--out is a file":
        out.write_text("x")
    else:
        args = case.split()
    blend = tmp_path / "scene.blend"
    blend.write_bytes(b"BLENDER")
    proc = subprocess.run([sys.executable, "-m", "hud_addon.batch", str(blend), "--out", str(out), *args],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and (case.split()[0] in lines[0] or str(out) in lines[0])


def test_hud_render_of_a_folder_named_like_a_blend_says_it_is_a_folder(tmp_path):
    """A folder x.blend was "no such .blend file"."""
    (tmp_path / "x.blend").mkdir()
    proc = subprocess.run([sys.executable, "-m", "hud_addon.batch", str(tmp_path / "x.blend"), "--out",
                           str(tmp_path / "out"), "--rays", "1000"], capture_output=True, text=True, timeout=120,
                          cwd=ROOT)
    assert proc.returncode == 2 and proc.stderr.strip().endswith("x.blend: a folder, not a .blend file"), proc.stderr


@pytest.mark.slow
def test_hud_render_of_a_file_blender_cannot_render_exits_2_in_one_line(tmp_path):
    """A file that is not a .blend was a traceback from open_mainfile, and Blender's own refusals (no
    camera) exit 1 as "error: Error: ..."; both are the input's fault: exit 2, our one line naming the file."""
    not_blend = tmp_path / "notes.blend"
    not_blend.write_text("not a blend file")
    empty = tmp_path / "empty.blend"
    made = subprocess.run([sys.executable, "-c", "import bpy; bpy.ops.wm.read_factory_settings(use_empty=True); "
                           f"bpy.ops.wm.save_as_mainfile(filepath={str(empty)!r})"], capture_output=True, text=True,
                          timeout=300, cwd=tmp_path)
    assert made.returncode == 0 and empty.is_file(), made.stderr[-2000:]
    for blend, words in ((not_blend, "not a readable .blend file"), (empty, "no camera")):
        out = tmp_path / f"out-{blend.stem}"
        proc = subprocess.run([sys.executable, "-m", "hud_addon.batch", str(blend), "--out", str(out), "--rays",
                               "100000"], capture_output=True, text=True, timeout=300, cwd=ROOT)
        ours = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr[-3000:]
        assert len(ours) == 1 and blend.name in ours[0] and words in ours[0], proc.stderr
        assert not out.exists() or not any(out.iterdir())


@pytest.mark.slow
def test_hud_render_says_each_warning_and_error_once(tmp_path):
    """Issue 31's walk-through: hud-render printed every warning and error twice, Blender's echo of the
    engine's report on standard output ("Warning: HUD Tracer: ...") and its own line on standard error.
    A .blend with a camera and no light: the dark-scene warning once, Blender's other lines kept, exit 3."""
    blend = tmp_path / "dark.blend"
    made = subprocess.run([sys.executable, "-c", "import bpy; bpy.ops.wm.read_factory_settings(use_empty=True); "
                           "bpy.ops.object.camera_add(location=(0, 0, 1)); "
                           "bpy.context.scene.camera = bpy.context.object; "
                           "bpy.ops.mesh.primitive_plane_add(size=1, location=(0, 0, -1)); "
                           "bpy.ops.object.light_add(type='POINT', location=(0, 0, 2)); "
                           f"bpy.ops.wm.save_as_mainfile(filepath={str(blend)!r})"], capture_output=True, text=True,
                          timeout=300, cwd=tmp_path)
    assert made.returncode == 0 and blend.is_file(), made.stderr[-2000:]
    proc = subprocess.run([sys.executable, "-m", "hud_addon.batch", str(blend), "--out", str(tmp_path / "out"),
                           "--rays", "100000"], capture_output=True, text=True, timeout=600, cwd=ROOT)
    # written, and exit 3 as hud-trace render for a render that found no light (it exited 0: a batch took
    # the black image for a result)
    assert proc.returncode == 3 and (tmp_path / "out" / "report.json").is_file(), proc.stderr[-3000:]
    both = proc.stdout + proc.stderr
    assert both.count("the scene has no light source") == 1, both
    assert "warning: the scene has no light source" in proc.stderr and "HUD Tracer:" not in proc.stdout
    # in Blender's terms (a second walk-through): the point light the user sees, and the plane left out
    assert "Point light 'Point' is not exported" in proc.stderr and "'Plane' has no optical role" in proc.stderr
    assert "Saved:" in proc.stdout  # Blender's own lines go on


@pytest.mark.slow
@pytest.mark.serial  # a LocalCluster of two worker processes
def test_hud_render_renders_on_a_dask_scheduler_the_same_image(tmp_path):
    """hud-render --scheduler (and the add-on's Dask Scheduler field, which it sets) on a LocalCluster gives
    the local image for a budget in rays. Inside Blender the tracer is a subpackage of the add-on
    (bl_ext.<repository>.hud_tracer.tracer), which Dask workers cannot import: every batch failed with
    "Error during deserialization of the task graph" (No module named 'bl_ext')."""
    distributed = pytest.importorskip("distributed")
    from tracer.core.imageio import read_exr_channels

    blend = tmp_path / "mirror.blend"
    made = subprocess.run([sys.executable, str(ROOT / "tools" / "preset_blend.py"), "analytic-mirror", str(blend)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert made.returncode == 0 and blend.is_file(), made.stderr[-3000:]
    render = [sys.executable, "-m", "hud_addon.batch", str(blend), "--rays", "400000", "--method", "backward",
              "--seed", "5"]
    local = subprocess.run([*render, "--out", str(tmp_path / "local")], capture_output=True, text=True, timeout=600,
                           cwd=ROOT)
    assert local.returncode == 0, local.stderr[-3000:]
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    with cluster:
        remote = subprocess.run([*render, "--out", str(tmp_path / "remote"), "--scheduler",
                                 cluster.scheduler_address], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert remote.returncode == 0 and "Traceback" not in remote.stderr, remote.stderr[-3000:]
    report = json.loads((tmp_path / "remote" / "report.json").read_text())
    assert report["workers"] == 2 and report["method_details"]["scheduler"] == cluster.scheduler_address
    a = read_exr_channels(tmp_path / "local" / "image.exr")[0]
    b = read_exr_channels(tmp_path / "remote" / "image.exr")[0]
    assert set(a) == set(b) and all(np.allclose(a[k], b[k], rtol=1e-6, atol=0) for k in a), sorted(a)
