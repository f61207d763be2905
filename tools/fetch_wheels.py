"""Download the pinned wheels that the Blender extension bundles into wheels/ (not committed).

    python tools/fetch_wheels.py

Blender ships numpy and OpenImageIO (its own Python has the OpenImageIO bindings), so the
extension carries embreex and what the charts need, matplotlib, contourpy, kiwisolver and pillow (one
wheel per platform each, cp311 for Blender 4.2-4.5), and the pure-Python trimesh, cycler, fonttools,
packaging, pyparsing, python-dateutil and tzdata, at requirements.lock's versions. The list must match
``wheels`` in blender_manifest.toml; this script checks that.
"""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: pip platform tags of each platform of the manifest (Linux: Blender's glibc 2.28 and older tags).
PLATFORMS = {"linux-x64": ("manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"),
             "windows-x64": ("win_amd64",), "macos-arm64": ("macosx_13_0_arm64", "macosx_11_0_arm64"),
             "macos-x64": ("macosx_13_0_x86_64", "macosx_10_12_x86_64", "macosx_10_9_x86_64")}
#: Projects with a wheel per platform, and pure-Python ones.
COMPILED = ("embreex", "matplotlib", "contourpy", "kiwisolver", "pillow")
PURE = ("trimesh", "cycler", "fonttools", "packaging", "pyparsing", "python-dateutil", "tzdata")


def pins() -> dict[str, str]:
    """requirements.lock's exact versions by project name."""
    out = {}
    for line in (ROOT / "requirements.lock").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, _, version = line.partition("==")
            out[name.lower()] = version
    return out


def requirements() -> list[tuple[str, tuple[str, ...] | None]]:
    """(requirement, pip platform tags, or None for a pure-Python wheel) of every wheel to fetch."""
    v = pins()
    out = [(f"{name}=={v[name]}", None) for name in PURE]
    out += [(f"{name}=={v[name]}", tags) for name in COMPILED for tags in PLATFORMS.values()]
    return out


def main() -> int:
    out = ROOT / "wheels"
    out.mkdir(exist_ok=True)
    for req, tags in requirements():
        cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
               "--dest", str(out), "--python-version", "3.11", req]
        if tags:
            cmd += ["--implementation", "cp", *(f"--platform={t}" for t in tags)]
        else:
            cmd += ["--implementation", "py", "--platform", "any"]
        subprocess.run(cmd, check=True)
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    wanted = {Path(w).name for w in manifest["wheels"]}
    have = {p.name for p in out.glob("*.whl")}
    missing = sorted(wanted - have)
    if missing:
        print(f"wheels listed in blender_manifest.toml but not downloaded: {missing}", file=sys.stderr)
        return 1
    print(f"{len(wanted)} wheels in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
