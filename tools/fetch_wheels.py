"""Download the pinned wheels that the Blender extension bundles into wheels/ (not committed).

    python tools/fetch_wheels.py

Blender ships numpy and OpenImageIO (its own Python has the OpenImageIO bindings), so the
extension carries only embreex (one wheel per platform, cp311 for Blender 4.2-4.5) and trimesh (pure
Python). The list must match ``wheels`` in blender_manifest.toml; this script checks that.
"""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: (requirement, pip platform tag or None for a pure-Python wheel)
WHEELS = [
    ("trimesh==4.12.2", None),
    ("embreex==4.4.0.post1", "manylinux_2_28_x86_64"),
    ("embreex==4.4.0.post1", "win_amd64"),
    ("embreex==4.4.0.post1", "macosx_13_0_arm64"),
    ("embreex==4.4.0.post1", "macosx_13_0_x86_64"),
]


def main() -> int:
    out = ROOT / "wheels"
    out.mkdir(exist_ok=True)
    for req, platform in WHEELS:
        cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
               "--dest", str(out), req]
        if platform:
            cmd += ["--python-version", "3.11", "--implementation", "cp", "--platform", platform]
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
