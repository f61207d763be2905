"""Which of the extension's platforms a wheel fits, from the tags in its file name (packaging.utils,
packaging.tags): used on blender_manifest.toml (tests/tools/test_extension.py) and on the zips built
from it (tests/addon/test_extension.py). No network."""

from __future__ import annotations

import re
from pathlib import Path

from packaging.tags import Tag, compatible_tags, cpython_tags, mac_platforms
from packaging.utils import parse_wheel_filename

#: Blender 4.2 to 4.5 run CPython 3.11.
PYTHON = (3, 11)
#: glibc of Blender 4.2+'s Linux builds (built on Rocky Linux 8; the bpy 4.2-4.5 wheels are manylinux_2_28).
BLENDER_GLIBC = (2, 28)


def macos_minimum(manifest_text: str, where: str = "blender_manifest.toml") -> tuple[int, int]:
    """The macOS version the manifest's comment states for the macOS zips ("macOS 13 or newer")."""
    found = re.findall(r"macOS (\d+) or newer", manifest_text)
    if len(found) != 1:
        raise AssertionError(f"{where}: expected one \"macOS <N> or newer\" in the comment on \"platforms\", "
                             f"found {found}")
    return int(found[0]), 0


def platform_tags(platform: str, macos: tuple[int, int]) -> list[str]:
    """Wheel platform tags that a Blender platform accepts: Linux x64 with Blender's glibc, Windows x64, macOS
    (arm64 or x64) at the given version."""
    if platform == "linux-x64":
        major, minor = BLENDER_GLIBC
        tags = [f"manylinux_{major}_{m}_x86_64" for m in range(minor, 4, -1)]
        aliases = {(2, 17): "manylinux2014_x86_64", (2, 12): "manylinux2010_x86_64", (2, 5): "manylinux1_x86_64"}
        return tags + [alias for glibc, alias in aliases.items() if glibc <= BLENDER_GLIBC]
    if platform == "windows-x64":
        return ["win_amd64"]
    if platform in ("macos-arm64", "macos-x64"):
        return list(mac_platforms(macos, "arm64" if platform == "macos-arm64" else "x86_64"))
    raise AssertionError(f"blender_manifest.toml: platforms: no wheel tags known for {platform!r}")


def python_tags(platforms: list[str]) -> set[Tag]:
    """Every tag that CPython 3.11 installs on these platforms, by packaging's rules (cp311-cp311, abi3,
    py3-none, ... and the pure-Python "any")."""
    return (set(cpython_tags(PYTHON, platforms=platforms))
            | set(compatible_tags(PYTHON, "cp311", platforms=platforms)))


def wheel_tags(path: str) -> frozenset[Tag]:
    return parse_wheel_filename(Path(path).name)[3]


def fits(platform: str, wheel: str, macos: tuple[int, int]) -> bool:
    """Whether CPython 3.11 on this Blender platform installs this wheel."""
    return bool(wheel_tags(wheel) & python_tags(platform_tags(platform, macos)))


def project(wheel: str) -> str:
    return str(parse_wheel_filename(Path(wheel).name)[0])
