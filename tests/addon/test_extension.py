"""The extension zip (tools/build_extension.py, as `make extension` builds it): it ships only what the add-on
uses, and installed in Blender it renders like the tracer, with Blender's own panels shown for the engine.

Each scenario (a ``scenario_*`` function: the scene set up, rendered or exported inside the bpy module)
sits before the tests that assert on its result, and runs in a process of its own through
tests/addon/blender_runner.py (tests.support.addon.in_blender)."""

from __future__ import annotations

import importlib.util
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from tests.support.addon import in_blender, needs_bpy, read_multilayer
from tests.support.paths import ROOT
from tests.support.render import render
from tests.support.stats import z_bound

pytestmark = [needs_bpy, pytest.mark.slow]


def _blender_ext() -> Path:
    """Blender's own extension tool, shipped inside the bpy package (bpy/<4.x>/scripts/..., found without
    importing bpy here): the tool of the bpy under test, 4.5 or the oldest the manifest allows (`make
    test-bpy-oldest`)."""
    (tool,) = Path(importlib.util.find_spec("bpy").origin).parent.glob("[0-9]*/scripts/addons_core/bl_pkg/cli/"
                                                                        "blender_ext.py")
    return tool


def _manifest() -> dict:
    import tomllib

    return tomllib.loads((ROOT / "blender_manifest.toml").read_text())


def _this_platform() -> str:
    """This machine as Blender names platforms in the manifest (linux-x64, windows-x64, macos-arm64, ...)."""
    import platform

    system = {"darwin": "macos", "win32": "windows"}.get(sys.platform, sys.platform)
    machine = {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64"}.get(platform.machine().lower(),
                                                                        platform.machine().lower())
    return f"{system}-{machine}"


@pytest.fixture(scope="session")
def extension_zip(tmp_path_factory):
    """Build the extension as `make extension` does (tools/build_extension.py: the pinned wheels fetched from
    PyPI, Blender's own tool with --split-platforms, every zip validated); the zip for this machine."""
    out = tmp_path_factory.mktemp("dist")
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / "build_extension.py"),
                           "--blender-ext", str(_blender_ext()), "--output-dir", str(out)],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    m = _manifest()
    return out / f"{m['id']}-{m['version']}-{_this_platform().replace('-', '_')}.zip"


def install_zip(zip_path: str) -> str:
    import bpy

    repo_dir = Path(tempfile.mkdtemp(prefix="hud-repo-")) / "hud_test"
    repo_dir.mkdir()
    bpy.ops.preferences.extension_repo_add(name="hud_test", type="LOCAL", use_custom_directory=True,
                                           custom_directory=str(repo_dir))
    repo = next(r.module for r in bpy.context.preferences.extensions.repos if r.custom_directory == str(repo_dir))
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo=repo, enable_on_install=True)
    return f"bl_ext.{repo}.hud_tracer"


#: Blender's own panels a user of HUD Tracer needs.
NEEDED_PANELS = ("RENDER_PT_format", "RENDER_PT_output", "RENDER_PT_frame_range", "RENDER_PT_color_management",
                 "DATA_PT_lens", "DATA_PT_uv_texture",
                 # issue 31's walk-through: Disable in Renders, a light's type, a World for a scene without one
                 "OBJECT_PT_visibility", "DATA_PT_context_light", "WORLD_PT_context_world")


def panels_with_engine() -> dict:
    import bpy

    return {n: "HUD_TRACER" in getattr(bpy.types, n).COMPAT_ENGINES for n in NEEDED_PANELS}


def render_preset(module: str, out: Path, preset: str, method: str, rays: int, seed: int) -> dict:
    import bpy

    bpy.ops.hud.add_preset(preset=preset)
    scene = bpy.context.scene
    scene.hud.method, scene.hud.budget, scene.hud.rays, scene.hud.seed = method, "RAYS", rays, seed
    s = scene.render.image_settings
    s.file_format, s.color_depth = "OPEN_EXR_MULTILAYER", "32"
    scene.render.filepath = str(out / "blender.exr")
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    bpy.ops.hud.export_scene(directory=str(out / "scene"))
    return dict(sys.modules[f"{module}.hud_addon.engine"].LAST_RENDER)


def scenario_install_render(zip_path, out, preset, method, rays, seed):
    import bpy

    from tests.support.blender import disable, hud_names

    module = install_zip(zip_path)
    enabled = module in bpy.context.preferences.addons
    panels = panels_with_engine()
    figures = render_preset(module, Path(out), preset, method, int(rays), int(seed))
    disable(module)
    return {"module": module, "enabled": enabled, "figures": figures, "left_after_disable": hud_names(),
            "panels": panels, "panels_after_disable": panels_with_engine(), "threads": bpy.context.scene.render.threads}


@pytest.mark.parametrize("method,rays", [("backward", 1_500_000), ("forward", 3_000_000)])
def test_installed_extension_renders_like_the_tracer(extension_zip, tmp_path, method, rays):
    """Install the zip, add a preset, F12 with write_still: the Render Result matches the tracer's own
    render of the exported scene folder within statistical error, and both match L R."""
    res, _ = in_blender(scenario_install_render, extension_zip, tmp_path, "analytic-mirror", method, rays, 7)
    assert res["enabled"] and res["module"].endswith(".hud_tracer")
    assert res["left_after_disable"] == []
    # Blender's Format, Output, Frame Range, Color Management, Lens and UV Maps panels show with HUD
    # Tracer as the engine, and no longer once it is disabled.
    assert all(res["panels"].values()) and not any(res["panels_after_disable"].values()), res["panels"]
    ch = read_multilayer(tmp_path / "blender.exr")
    rgb = np.stack([ch["ViewLayer.Combined.R"], ch["ViewLayer.Combined.G"], ch["ViewLayer.Combined.B"]], -1)
    y_blender = rgb @ np.array([0.2126, 0.7152, 0.0722])
    np.testing.assert_allclose(ch["ViewLayer.Y.X"], y_blender, rtol=1e-5, atol=1e-4)
    y_tracer, var, result = render(tmp_path / "scene", method, rays, seed=7)
    assert y_blender.shape == y_tracer.shape
    # Blender renders on a pool of Performance > Threads processes; for a budget in rays that is the
    # same image as the tracer's one-process render of the exported folder (seed-addressed batches), to
    # float32 rounding, and its noise pass is the standard error the tracer reports.
    assert res["figures"]["workers"] == res["threads"] and res["figures"]["rays"] == result.rays
    np.testing.assert_allclose(y_blender, y_tracer, rtol=1e-5, atol=1e-6 * y_tracer.max())
    np.testing.assert_allclose(ch["ViewLayer.Y_noise.X"], np.sqrt(var), rtol=1e-4, atol=1e-6 * np.sqrt(var).max())
    covered = (y_tracer > 425) & (y_blender > 425)
    assert covered.sum() > 100
    sem = math.sqrt(var[covered].sum()) / covered.sum()
    assert abs(y_blender[covered].mean() - 850.0) < z_bound(1) * sem + 0.01 * 850
    # The hud:* fields of the command line's image.exr are in the header of the EXR Blender wrote.
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(tmp_path / "blender.exr"))
    header = {a.name: a.value for a in inp.spec().extra_attribs}
    inp.close()
    assert header["hud:method"] == method and header["hud:run_id"] == res["figures"]["run_id"]
    assert int(header["hud:rays"]) == result.rays and "Y_noise" in header["hud:units"]


def test_extension_zip_ships_only_what_the_add_on_uses(extension_zip):
    """One zip per platform of the manifest, named by Blender's tool; each holds the
    license, the manifest (its generated table naming its platform and wheels), tracer/, hud_addon/,
    presets/, exactly one wheel of each project the manifest lists (embreex, trimesh, matplotlib and what it
    needs), each for its platform or pure Python; nothing the add-on does not use (tests, benchmarks, docs,
    README, locks, Makefile, tools, .ci, .git, caches). The Dask driver ships (Blender's Dask Scheduler
    field: issue 31), Dask does not."""
    import tomllib
    import zipfile

    from tests.support.wheel_tags import fits, macos_minimum, project

    m = _manifest()
    macos = macos_minimum((ROOT / "blender_manifest.toml").read_text())
    names = {p: f"{m['id']}-{m['version']}-{p.replace('-', '_')}.zip" for p in m["platforms"]}
    dist = extension_zip.parent
    assert sorted(z.name for z in dist.iterdir()) == sorted(names.values()), "the zips made by the build"
    # Every file of the add-on's packages, as the build sees them on disk (untracked ones too).
    shipped = {p.relative_to(ROOT).as_posix() for d in ("tracer", "hud_addon", "presets")
               for p in (ROOT / d).rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    for platform, name in names.items():
        z = zipfile.ZipFile(dist / name)
        entries = [n for n in z.namelist() if not n.endswith("/")]
        top = {n.split("/")[0] for n in entries}
        wanted = {"LICENSE", "blender_manifest.toml", "__init__.py", "tracer", "hud_addon", "presets", "wheels"}
        assert top == wanted, f"{name}: unused {sorted(top - wanted)}, missing {sorted(wanted - top)}"
        code = {n for n in entries if n.startswith(("tracer/", "hud_addon/", "presets/"))}
        assert code == shipped, f"{name}: unused {sorted(code - shipped)}, missing {sorted(shipped - code)}"
        for unused in ("README.md", "Makefile", "requirements.lock", "requirements-bench.lock", ".git", ".gitignore"):
            assert unused not in entries, (name, unused)
        assert not any(n.startswith(("tests/", "benchmarks/", "docs/", "tools/", ".ci/", ".venv")) or n.endswith(".pyc")
                       for n in entries), name
        wheels = sorted(n for n in entries if n.startswith("wheels/"))
        # One wheel of every project the manifest lists, each for this platform (or pure Python).
        assert sorted(project(w) for w in wheels) == sorted({project(w) for w in m["wheels"]}), (name, wheels)
        assert all(fits(platform, w, macos) for w in wheels), (name, wheels)
        generated = tomllib.loads(z.read("blender_manifest.toml").decode())["build"]["generated"]
        assert generated["platforms"] == [platform], (name, generated)
        assert sorted(w.removeprefix("./") for w in generated["wheels"]) == wheels, (name, generated)
        assert z.read("LICENSE") == (ROOT / "LICENSE").read_bytes(), name
