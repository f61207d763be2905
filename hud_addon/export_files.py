"""The files of an export: unique readable names, meshes and images planned (each checked when planned)
and written into a staging folder, the staged folder checked, and the target folder's rules (an export
replaces its folder as a whole, and only an empty one or an earlier export)."""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import bpy
import numpy as np

from ..presets._build import write_obj
from ..tracer.core.imageio import TEXTURE_ATTRIBUTES, write_exr
from ..tracer.optics.materials import MATERIALS

#: What an export folder holds; a folder holding anything else is not replaced (see check_replaceable).
EXPORT_ENTRIES = frozenset({"scene.json", "meshes", "textures"})


#: Files the file manager of an OS puts into any folder it shows: replaced along with an export.
_OS_FILES = frozenset({".DS_Store", "Thumbs.db", "desktop.ini"})


#: File names Windows refuses whatever their extension.
_WINDOWS_RESERVED = frozenset({"CON", "PRN", "AUX", "NUL", *(f"COM{i}" for i in range(1, 10)),
                               *(f"LPT{i}" for i in range(1, 10))})


class FileNames:
    """Unique, readable file stems within one folder of the export.

    A stem is the name made safe for file systems (``bpy.path.clean_name``); when that stem is taken,
    "-2", "-3", ... is appended. Stems are compared case-insensitively, so that no two files of an
    export collide on the case-insensitive file systems of Windows and macOS either. The same claims
    in the same order give the same stems.
    """

    def __init__(self):
        self._taken: set[str] = set()

    def claim(self, name: str) -> str:
        base = bpy.path.clean_name(name) or "unnamed"
        if base.upper() in _WINDOWS_RESERVED:
            base += "_"
        stem, k = base, 1
        while stem.casefold() in self._taken:
            k += 1
            stem = f"{base}-{k}"
        self._taken.add(stem.casefold())
        return stem


class Plan:
    """The files of one export, each checked when it is planned and written only by :meth:`write`.

    ``files`` maps a path relative to the export folder to the function that writes it (given the
    absolute path to write to).
    """

    def __init__(self):
        self.files: dict[str, Callable[[Path], None]] = {}
        self.textures = FileNames()

    def add(self, rel: str, write: Callable[[Path], None]) -> str:
        assert rel not in self.files, rel  # stems are unique
        self.files[rel] = write
        return rel

    def image(self, image, name: str, what: str) -> str:
        """Plan a texture file for ``image`` named after ``name`` (made unique); returns its path
        relative to the folder. Raises ValueError, naming ``what``, the image and, for an image
        kept in a file, the file's path, when the image cannot be read."""
        suffix, write = image_writer(image, what)
        return self.add(f"textures/{self.textures.claim(name)}{suffix}", write)

    def write(self, folder: Path):
        """Write every planned file under ``folder``."""
        for rel, write in self.files.items():
            path = folder / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            write(path)


def image_writer(image, what: str) -> tuple[str, Callable[[Path], None]]:
    """(file suffix, write(path)) of an image, checked now: an image kept in a file (not packed) is
    copied as it is, and that file must exist and be readable; a packed or generated image is
    written as EXR with its pixel values as stored, and must have pixels.

    Raises ValueError "<what> image '<name>' cannot be read: <path> (<reason>)" or
    "<what> image '<name>' has no pixels".
    """
    label = f"{what} image {image.name!r}"
    raw = image.filepath_raw or image.filepath
    src = Path(bpy.path.abspath(raw)) if raw else None
    from_file = image.packed_file is None and src is not None and (image.source == "FILE" or src.is_file())
    if from_file:
        reason = None
        if not src.exists():
            reason = "file not found"
        elif not src.is_file():
            reason = "not a file"
        else:
            try:
                with open(src, "rb") as fh:
                    if not fh.read(1):
                        reason = "empty file"
            except OSError as e:
                reason = e.strerror or str(e)
        if reason is not None:
            raise ValueError(f"{label} cannot be read: {src} ({reason})")
        return src.suffix.lower(), lambda path: shutil.copyfile(src, path)
    w, h = image.size
    if w == 0 or h == 0:
        raise ValueError(f"{label} has no pixels")

    def write(path: Path):
        px = np.empty(w * h * image.channels, dtype=np.float32)
        image.pixels.foreach_get(px)
        px = px.reshape(h, w, image.channels)[::-1]  # Blender's row 0 is the bottom row
        rgb = px[..., :3] if image.channels >= 3 else np.repeat(px[..., :1], 3, axis=2)
        write_exr(path, {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]}, TEXTURE_ATTRIBUTES)

    return ".exr", write


def mesh_writer(co: np.ndarray, tri: np.ndarray, uv, mm: float) -> Callable[[Path], None]:
    """write(path) of a mesh's arrays as OBJ in millimetres."""
    return lambda path: write_obj(path, co * mm, tri, uv)


def image_fields(block: dict, fields) -> list[str]:
    """The image paths of a (material) block, groups included."""
    out = []
    for f in fields:
        if f.name in block and f.kind == "image":
            out.append(block[f.name])
        elif f.name in block and f.kind == "group":
            out += image_fields(block[f.name], f.fields)
    return out


def check_staged(staging: Path, target: Path, planned) -> None:
    """Raise ValueError unless scene.json in ``staging`` parses and every file it references, and
    every planned file, exists there and is not empty."""
    try:
        data = json.loads((staging / "scene.json").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"the export to {target} could not be checked: scene.json: {e}") from None
    refs = set(planned)
    for o in data["objects"]:
        refs.add(o["mesh"])
        refs.update(image_fields(o["material"], MATERIALS[o["material"]["type"]].schema.fields))
    if "file" in data["environment"]:
        refs.add(data["environment"]["file"])
    bad = [rel for rel in sorted(refs) if not (staging / rel).is_file() or (staging / rel).stat().st_size == 0]
    if bad:
        raise ValueError(f"the export to {target} is incomplete: {', '.join(bad)} missing or empty")


def target_folder(folder) -> Path:
    """The absolute folder an export replaces: a symbolic link is followed (the link stays valid)."""
    target = Path(os.path.abspath(folder))
    if target.is_symlink():
        target = Path(os.path.realpath(target))
    if not target.name:
        raise ValueError(f"cannot export into {target}: choose a folder (it is replaced as a whole)")
    return target


def check_replaceable(target: Path) -> None:
    """Raise ValueError unless ``target`` is absent, empty, or an earlier export (scene.json, meshes/,
    textures/ and nothing else): an export replaces its folder as a whole, and must never take a
    user's other files with it."""
    if not target.exists():
        return
    if not target.is_dir():
        raise ValueError(f"cannot export into {target}: it is a file, not a folder")
    entries = {p.name for p in target.iterdir()} - _OS_FILES
    if not entries:
        return
    foreign = sorted(entries - EXPORT_ENTRIES)
    if foreign or "scene.json" not in entries:
        what = ", ".join(foreign[:5]) + (", ..." if len(foreign) > 5 else "") if foreign else "no scene.json"
        raise ValueError(f"cannot export into {target}: it holds files that are not a HUD scene export ({what}); "
                         "choose an empty or new folder, or an earlier export (an export replaces its folder as a "
                         "whole)")
