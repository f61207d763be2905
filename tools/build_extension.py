"""Build the Blender extension: one zip per platform of blender_manifest.toml, each one validated.

    python tools/build_extension.py [--output-dir dist] [--blender-ext PATH/TO/blender_ext.py]

`make extension` and the add-on tests (tests/addon/test_extension.py) both build through this script, so
the tests check the zips that `make extension` makes. It runs tools/fetch_wheels.py (the pinned wheels
into wheels/), then Blender's own extension tool, blender_ext.py (shipped inside the bpy package; by
default the one of the bpy installed beside this Python):

    blender_ext.py build --split-platforms --source-dir <staging copy> --output-dir <dir>
    blender_ext.py validate <zip>                      (for every zip the build made)

Blender's tool packs every file of its source folder that the manifest's ``paths_exclude_pattern`` does
not exclude, so a user's own files in the checkout (a scene.blend, a scenes/ folder of exports) would
ship too. The build therefore runs on a staging copy of only what the add-on is made of
(:data:`SHIPPED`: the manifest, __init__.py, LICENSE, tracer/, hud_addon/, presets/ and the wheels the
manifest lists), from which the manifest's patterns still drop caches.

``--split-platforms`` makes one zip per platform of the manifest, named
``<id>-<version>-<platform, "-" as "_">.zip`` (hud_tracer-0.1.0-linux_x64.zip, ...), each carrying the
wheels that Blender's tool matches to its platform (its embreex wheel and the pure-Python trimesh) and a
manifest with a generated ``[build.generated]`` table naming that platform and those wheels. Earlier
zips of this id and version in the output folder are removed first, so every zip left there comes from
this build. Prints each zip's name and size.
"""

from __future__ import annotations

import argparse
import importlib.util
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "blender_manifest.toml"
#: What the extension is made of: the only entries of the checkout's root that the build sees.
SHIPPED = ("blender_manifest.toml", "__init__.py", "LICENSE", "tracer", "hud_addon", "presets")


def stage_sources(root: Path, manifest: dict, staging: Path) -> None:
    """Copy :data:`SHIPPED` and the wheels ``manifest`` lists from ``root`` into ``staging`` (caches left
    out), the source folder Blender's tool packs."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in SHIPPED:
        source = root / name
        if source.is_dir():
            shutil.copytree(source, staging / name, ignore=ignore)
        else:
            shutil.copy2(source, staging / name)
    (staging / "wheels").mkdir()
    for wheel in manifest.get("wheels", []):
        shutil.copy2(root / wheel, staging / wheel)


def find_blender_ext() -> Path:
    """blender_ext.py of the bpy package importable here (bpy/<4.x>/scripts/addons_core/bl_pkg/cli/), found
    without importing bpy."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise SystemExit("build_extension: the bpy module is not installed here; pass --blender-ext")
    found = sorted(Path(spec.origin).parent.glob("[0-9]*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if len(found) != 1:
        raise SystemExit(f"build_extension: expected one blender_ext.py in {Path(spec.origin).parent}, found {found}")
    return found[0]


def zip_names(manifest: dict) -> dict[str, str]:
    """Platform -> the file name Blender's tool gives that platform's zip (blender_ext.py build --split-platforms)."""
    return {p: f"{manifest['id']}-{manifest['version']}-{p.replace('-', '_')}.zip" for p in manifest["platforms"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--output-dir", type=Path, default=ROOT / "dist")
    ap.add_argument("--blender-ext", type=Path, default=None, help="Blender's blender_ext.py (default: bpy's own)")
    args = ap.parse_args(argv)
    blender_ext = args.blender_ext or find_blender_ext()
    manifest = tomllib.loads(MANIFEST.read_text())
    if not manifest.get("platforms"):
        print(f"{MANIFEST}: \"platforms\" is missing or empty; --split-platforms needs it", file=sys.stderr)
        return 1
    names = zip_names(manifest)

    subprocess.run([sys.executable, str(ROOT / "tools" / "fetch_wheels.py")], check=True, cwd=ROOT)
    out = args.output_dir.resolve()
    out.mkdir(parents=True, exist_ok=True)
    for stale in out.glob(f"{manifest['id']}-{manifest['version']}*.zip"):
        stale.unlink()
    with tempfile.TemporaryDirectory(prefix="hud-extension-") as staging:
        stage_sources(ROOT, manifest, Path(staging))
        build = subprocess.run([sys.executable, str(blender_ext), "build", "--split-platforms",
                                "--source-dir", staging, "--output-dir", str(out)], capture_output=True, text=True)
    if build.returncode != 0:
        print(f"{blender_ext} build failed:\n{build.stdout}{build.stderr}", file=sys.stderr)
        return 1
    made = sorted(p.name for p in out.glob(f"{manifest['id']}-{manifest['version']}*.zip"))
    if made != sorted(names.values()):
        print(f"{blender_ext} build made {made}, expected one zip per platform of {MANIFEST.name}: "
              f"{sorted(names.values())}", file=sys.stderr)
        return 1
    for platform, name in names.items():
        check = subprocess.run([sys.executable, str(blender_ext), "validate", str(out / name)],
                               capture_output=True, text=True)
        if check.returncode != 0:
            print(f"{out / name}: {blender_ext.name} validate failed:\n{check.stdout}{check.stderr}", file=sys.stderr)
            return 1
        size = (out / name).stat().st_size
        print(f"{out / name}  {platform}  {size / 1e6:.1f} MB ({size} bytes), validated")
    return 0


if __name__ == "__main__":
    sys.exit(main())
