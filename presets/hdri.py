"""Real HDR panoramas for environments, and the figures that calibrate them.

Blender ships eight equirectangular HDR panoramas as its studio lights (``datafiles/studiolights/world``:
city, courtyard, forest, interior, night, studio, sunrise, sunset; 1024 x 512 EXR, CC0, from Poly
Haven, clamped to [0, 32000] before their lossy compression: license.txt beside them).
:func:`studio_hdri` finds them inside the installed bpy package without importing it (importing bpy
takes seconds), so a preset can use a real environment without committing an image;
:func:`copy_panorama` puts one into a scene folder as the tracer reads it. :func:`panorama_stats`
gives the luminance figures of a panorama file (its own values, before any calibration) that a
calibration picks from.

Blender stores these panoramas with lossy DWAB compression, whose ringing leaves a few colour
components slightly below zero (measured in bpy 4.5.15: 7 of the 8 files, up to 826 of their 1.6 M
values in forest.exr, the lowest -0.0022 against a mean luminance of 0.77; no pixel's luminance is
negative). The tracer refuses negative radiance, so :func:`copy_panorama` sets those components to 0.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

try:  # inside the Blender extension, presets and tracer are subpackages of the extension package
    from ..tracer.core.imageio import TEXTURE_ATTRIBUTES, read_image, write_exr
    from ..tracer.core.units import luminance
    from ..tracer.sources.environment import panorama_rgb, row_solid_angle_fractions
except ImportError:  # presets and tracer as top-level packages (command line, tests)
    from tracer.core.imageio import TEXTURE_ATTRIBUTES, read_image, write_exr
    from tracer.core.units import luminance
    from tracer.sources.environment import panorama_rgb, row_solid_angle_fractions

#: The panoramas of Blender's studio lights (``<name>.exr``).
STUDIO_HDRIS = ("city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset")
#: The bpy release the project pins (requirements.lock), for the message when none is installed.
BPY_PIN = "bpy==4.5.15"
#: Where the panoramas lie inside a Blender release folder.
_WORLD = Path("datafiles", "studiolights", "world")


def _version_key(folder: Path) -> tuple:
    """Sort key of a release folder named like "4.5": its numbers."""
    return tuple(int(p) if p.isdigit() else -1 for p in folder.name.split("."))


def _world_folders() -> list[Path]:
    """Folders that may hold the studio panoramas, newest release first: the bpy package of PyPI keeps
    them in ``bpy/<version>/datafiles``; inside Blender itself bpy is ``<version>/scripts/modules/bpy``."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.origin or not Path(spec.origin).is_file():
        return []
    package = Path(spec.origin).parent
    releases = sorted((p for p in package.glob("[0-9]*") if p.is_dir()), key=_version_key, reverse=True)
    return [r / _WORLD for r in releases] + [package.parents[2] / _WORLD]


def studio_hdri(name: str) -> Path:
    """The path of Blender's studio-light panorama ``name`` (one of :data:`STUDIO_HDRIS`), found through
    ``importlib.util.find_spec("bpy")`` without importing bpy.

    Raises
    ------
    ValueError
        An unknown name (the message lists the names), or a panorama that no installed bpy provides
        (the message says that the bpy package provides it, how to install it, and that a panorama
        file can be given instead).
    """
    if name not in STUDIO_HDRIS:
        raise ValueError(f"no studio panorama {name!r}; Blender ships {', '.join(STUDIO_HDRIS)}")
    for folder in _world_folders():
        path = folder / f"{name}.exr"
        if path.is_file():
            return path
    raise ValueError(f"the HDR panorama {name!r} ({_WORLD.as_posix()}/{name}.exr) is provided by Blender's bpy "
                     f"package, which is not installed here: pip install {BPY_PIN}, or give a panorama file "
                     "instead")


def panorama_stats(path) -> dict:
    """Luminance figures of an equirectangular panorama file, in the file's own linear units (Y of its
    pixels, before any calibration): a calibration's k is the target luminance over one of them.

    - ``min``, ``max``: the smallest and largest pixel luminance (the measures of the "min" and "max"
      calibrations);
    - ``mean``: the solid-angle-weighted mean, exactly :class:`tracer.sources.environment.HdriEnvironment`'s
      (the measure of the "mean" calibration): each pixel weighs its row's exact solid angle
      (:func:`tracer.sources.environment.row_solid_angle_fractions`);
    - ``p01``, ``p99``: the 1st and 99th percentiles over the sphere: the smallest pixel luminance
      such that the pixels at or below it cover at least 1 % (99 %) of the sphere's solid angle (pixel
      counts would overweight the rows near the poles, which an equirectangular image stretches);
    - ``black_pixels``: pixels of zero luminance (a "min" calibration refuses a panorama with one);
    - ``negative_values``: colour components below zero (the tracer refuses a panorama with one; see
      :func:`copy_panorama`);
    - ``width``, ``height``: the image's size in pixels.

    Raises ImageReadError for a file that cannot be read, ValueError for one with more than 4 channels.
    """
    rgb = panorama_rgb(read_image(Path(path)))
    y = luminance(rgb)
    h, w = y.shape
    fractions = row_solid_angle_fractions(h)
    order = np.argsort(y, axis=None, kind="stable")
    covered = np.cumsum(np.broadcast_to(fractions[:, None] / w, (h, w)).ravel()[order])
    values = y.ravel()[order]

    def percentile(q: float) -> float:
        return float(values[min(int(np.searchsorted(covered, q * covered[-1])), len(values) - 1)])

    return {"min": float(y.min()), "mean": float(fractions @ y.mean(axis=1)), "max": float(y.max()),
            "p01": percentile(0.01), "p99": percentile(0.99), "black_pixels": int(np.count_nonzero(y == 0.0)),
            "negative_values": int(np.count_nonzero(rgb < 0.0)), "width": w, "height": h}


def copy_panorama(source, destination) -> int:
    """Write the panorama file ``source`` as a float RGB EXR at ``destination`` (a scene folder's
    texture), its colour components below zero set to 0 (module docstring); returns how many were.

    Raises ImageReadError for a file that cannot be read, ValueError for one with more than 4 channels.
    """
    rgb = panorama_rgb(read_image(Path(source)))
    negative = int(np.count_nonzero(rgb < 0.0))
    rgb = np.maximum(rgb, 0.0)
    destination = Path(destination)
    destination.parent.mkdir(parents=True, exist_ok=True)
    write_exr(destination, {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]}, TEXTURE_ATTRIBUTES)
    return negative
