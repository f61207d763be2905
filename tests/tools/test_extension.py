"""The Blender extension's manifest against the wheels it lists, from the wheels' file names alone (no
network, no bpy): every wheel installs on Blender 4.2-4.5's Python 3.11, each platform the manifest claims
gets exactly one wheel of every compiled project (embreex, matplotlib and what it needs) that runs there,
with what that needs beyond Blender itself (macOS 13 for embreex 4.4's macOS wheels) stated in the manifest
and the README, and the wheels are requirements.lock's versions; the oldest-bpy lock, and the build
(tools/build_extension.py) stages the add-on's entries and listed wheels alone."""

import tomllib

import pytest
from packaging.utils import canonicalize_name
from packaging.version import Version

from tests.support.paths import ROOT
from tests.support.wheel_tags import fits, macos_minimum, project, python_tags, wheel_tags

MANIFEST_TEXT = (ROOT / "blender_manifest.toml").read_text()
MANIFEST = tomllib.loads(MANIFEST_TEXT)
MACOS = macos_minimum(MANIFEST_TEXT)


def test_the_manifest_claims_blender_4_2_to_4_5():
    """The wheels' Python (cp311) is Blender 4.2-4.5's; Blender 5 runs Python 3.13."""
    assert (MANIFEST["blender_version_min"], MANIFEST["blender_version_max"]) == ("4.2.0", "5.0.0")


@pytest.mark.parametrize("wheel", MANIFEST["wheels"])
def test_every_wheel_installs_on_python_3_11(wheel):
    python_3_11 = {(t.interpreter, t.abi) for t in python_tags(["any"])}  # cp311-cp311, cp3x-abi3, py3-none...
    assert {(t.interpreter, t.abi) for t in wheel_tags(wheel)} & python_3_11, (
        f"blender_manifest.toml: wheels: {wheel} is not for CPython 3.11 (Blender 4.2-4.5): "
        f"{sorted(map(str, wheel_tags(wheel)))}")
    if project(wheel) in COMPILED:  # built for CPython 3.11's own ABI
        assert {(t.interpreter, t.abi) for t in wheel_tags(wheel)} == {("cp311", "cp311")}, (
            f"blender_manifest.toml: wheels: {wheel} is not a cp311-cp311 wheel")


#: The projects whose wheels are compiled, one per platform; every other wheel is pure Python.
COMPILED = {project(w) for w in MANIFEST["wheels"] if not any(t.platform == "any" for t in wheel_tags(w))}


@pytest.mark.parametrize("platform", MANIFEST["platforms"])
def test_each_platform_has_exactly_one_wheel_of_each_compiled_project_that_fits_it(platform):
    assert {"embreex", "matplotlib"} <= COMPILED
    for name in sorted(COMPILED):
        found = [w for w in MANIFEST["wheels"] if project(w) == name and fits(platform, w, MACOS)]
        assert len(found) == 1, (f"blender_manifest.toml: wheels: {len(found)} {name} wheels for the platform "
                                 f"{platform!r} (glibc 2.28, macOS {MACOS[0]}): {found}")
    pure = [w for w in MANIFEST["wheels"] if project(w) not in COMPILED]
    assert pure and all(fits(platform, w, MACOS) for w in pure), (
        f"blender_manifest.toml: wheels: not every other wheel fits {platform!r}: {pure}")


def test_the_wheels_are_the_locked_versions_and_numpy_is_not_bundled():
    """What the extension bundles is what `make demo` installs (requirements.lock); numpy is Blender's."""
    from packaging.utils import parse_wheel_filename

    locked = _pins("requirements.lock")
    for wheel in MANIFEST["wheels"]:
        name, version = parse_wheel_filename(wheel.rsplit("/", 1)[-1])[:2]
        assert locked.get(canonicalize_name(name)) == str(version), (wheel, locked.get(canonicalize_name(name)))
    assert "numpy" not in {project(w) for w in MANIFEST["wheels"]}


def test_no_wheel_is_for_a_platform_the_manifest_does_not_claim():
    stray = [w for w in MANIFEST["wheels"] if not any(fits(p, w, MACOS) for p in MANIFEST["platforms"])]
    assert stray == [], f"blender_manifest.toml: wheels: fit none of {MANIFEST['platforms']}: {stray}"


def test_the_stated_macos_minimum_is_what_the_macos_wheels_need():
    """"macOS 13 or newer" in the manifest's comment and in the README is exactly the embreex wheels' macOS
    tag: they do not fit macOS 12 (which Blender 4.2-4.5 support), so the statement is needed, and no
    lower version would do."""
    older = (MACOS[0] - 1, 0)
    for platform in ("macos-arm64", "macos-x64"):
        if platform not in MANIFEST["platforms"]:
            continue
        found = [w for w in MANIFEST["wheels"] if project(w) == "embreex" and fits(platform, w, MACOS)]
        assert len(found) == 1, f"blender_manifest.toml: wheels: embreex wheels for {platform!r}: {found}"
        assert not fits(platform, found[0], older), (
            f"blender_manifest.toml: {found[0]} runs on macOS {older[0]}: the comment on \"platforms\" "
            f"says macOS {MACOS[0]} or newer")
    readme = (ROOT / "README.md").read_text()
    assert f"macOS {MACOS[0]} or newer" in readme, f"README.md: does not say \"macOS {MACOS[0]} or newer\""


def test_the_tag_rules_reject_what_does_not_run():
    """The rules above tell wheels apart: another Python, a newer glibc or macOS, another architecture."""
    assert fits("linux-x64", "e-1-cp311-cp311-manylinux_2_28_x86_64.whl", MACOS)
    assert fits("linux-x64", "e-1-cp311-cp311-manylinux2014_x86_64.whl", MACOS)
    assert not fits("linux-x64", "e-1-cp311-cp311-manylinux_2_34_x86_64.whl", MACOS)
    assert not fits("linux-x64", "e-1-cp311-cp311-manylinux_2_28_aarch64.whl", MACOS)
    assert not fits("linux-x64", "e-1-cp313-cp313-manylinux_2_28_x86_64.whl", MACOS)
    assert not fits("linux-x64", "e-1-cp311-cp311-linux_x86_64.whl", MACOS)
    assert fits("windows-x64", "e-1-cp311-cp311-win_amd64.whl", MACOS)
    assert not fits("windows-x64", "e-1-cp311-cp311-win32.whl", MACOS)
    assert fits("macos-arm64", "e-1-cp311-cp311-macosx_11_0_arm64.whl", (11, 0))
    assert fits("macos-arm64", "e-1-cp311-cp311-macosx_10_9_universal2.whl", (11, 0))
    assert not fits("macos-arm64", "e-1-cp311-cp311-macosx_13_0_arm64.whl", (12, 0))
    assert not fits("macos-x64", "e-1-cp311-cp311-macosx_13_0_arm64.whl", (13, 0))
    assert fits("macos-x64", "t-1-py3-none-any.whl", (11, 0))
    assert fits("windows-x64", "e-1-cp38-abi3-win_amd64.whl", MACOS)


def _pins(name: str) -> dict[str, str]:
    pins = {}
    for n, line in enumerate((ROOT / name).read_text().splitlines(), 1):
        line = line.split("#")[0].strip()
        if line:
            package, sep, version = line.partition("==")
            assert sep and version, f"{name}, line {n}: not an exact pin: {line!r}"
            pins[canonicalize_name(package)] = version
    return pins


def test_the_oldest_bpy_lock_is_requirements_lock_with_the_manifests_oldest_bpy():
    """`make test-bpy-oldest` runs the add-on tests on the bpy of blender_version_min, every other package
    as requirements.lock and requirements-test.lock pin it."""
    oldest, main = _pins("requirements-bpy42.lock"), _pins("requirements.lock") | _pins("requirements-test.lock")
    minimum = Version(MANIFEST["blender_version_min"]).release[:2]
    assert Version(oldest.get("bpy", "0")).release[:2] == minimum, (
        f"requirements-bpy42.lock: bpy {oldest.get('bpy')} is not blender_version_min's {minimum}")
    differ = {k: (v, main.get(k)) for k, v in oldest.items() if k != "bpy" and main.get(k) != v}
    assert differ == {}, f"requirements-bpy42.lock: pins that differ from requirements.lock: {differ}"
    needed = {"numpy", "embreex", "trimesh", "openimageio", "matplotlib", "pytest", "setuptools"}
    assert needed <= oldest.keys(), f"requirements-bpy42.lock: missing {sorted(needed - oldest.keys())}"


def test_the_build_packs_a_staging_copy_of_the_add_on_only(tmp_path):
    """Blender's tool packs its whole source folder but for the manifest's patterns: a scene.blend and an
    exported scenes/ folder in the checkout (hud-render's and hud-trace export's own README examples)
    shipped in every zip. tools/build_extension.py stages the add-on's entries and listed wheels alone."""
    import importlib.util
    import shutil

    spec = importlib.util.spec_from_file_location("build_extension", ROOT / "tools" / "build_extension.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    root = tmp_path / "checkout"
    root.mkdir()
    for name in build.SHIPPED:
        source = ROOT / name
        if source.is_dir():
            (root / name / "sub").mkdir(parents=True)
            (root / name / "module.py").write_text("x = 1\n")
            (root / name / "__pycache__").mkdir()
            (root / name / "__pycache__" / "module.cpython-311.pyc").write_bytes(b"\0")
        else:
            shutil.copy2(source, root / name)
    (root / "wheels").mkdir()
    for wheel in MANIFEST["wheels"] + ["./wheels/numpy-1.26.4-cp311-cp311-win_amd64.whl"]:
        (root / wheel).write_bytes(b"PK")
    (root / "scene.blend").write_bytes(b"BLENDER")
    (root / "scenes" / "hd").mkdir(parents=True)
    (root / "scenes" / "hd" / "scene.json").write_text("{}")
    staging = tmp_path / "staging"
    staging.mkdir()
    build.stage_sources(root, MANIFEST, staging)
    found = {p.relative_to(staging).as_posix() for p in staging.rglob("*") if p.is_file()}
    wheels = {w.removeprefix("./") for w in MANIFEST["wheels"]}
    code = {f"{name}/module.py" for name in build.SHIPPED if (ROOT / name).is_dir()}
    files = {name for name in build.SHIPPED if (ROOT / name).is_file()}
    assert found == code | files | wheels, sorted(found ^ (code | files | wheels))
    assert {"blender_manifest.toml", "__init__.py", "LICENSE"} <= files
