"""Validation of JSON fields for the scene format: one checker for every block of scene.json; and of
what a render asks of the machine (memory for its film, worker processes).

Every number has a physical range. Beyond it a value cannot describe a HUD, an eye or their
surroundings, and arithmetic would overflow (images are float32, up to 3.4e38; a luminance squared
is a variance). The limits below are generous by orders of magnitude; a number without a field-
specific range must still lie within +-:data:`MAX_ABS`.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from .errors import SceneError

#: Largest magnitude of any number in scene.json (fields with their own range have tighter ones).
MAX_ABS = 1e15
#: Largest luminance, cd/m^2: a thousand times the sun's disk (1.6e9).
MAX_LUMINANCE = 1e12
#: The smallest positive luminance of a light (an emitter, the environment, the sun's disk), cd/m^2: a
#: thousandth of the eye's absolute threshold (about 1e-6); below it the float32 path weights of a few
#: optical events underflow to zero and the image would come out black without a warning.
MIN_LUMINANCE = 1e-9
#: The smallest positive factor (a transmittance, reflectance or share of a field in [0, 1]): float32 path
#: weights hold about 1e-38, and a path meets several such factors (an analyser's 1e-40 overflowed a
#: reciprocal, 1e-300 rendered black with exit 0).
MIN_FACTOR = 1e-9
#: Largest luminous flux of one object, lm (a stadium's floodlights are about 1e8).
MAX_FLUX = 1e10
#: Every position (eye, translations, mesh vertices in the world) lies within this distance of the
#: origin along each axis, mm (10 km; an HDRI stands for what is farther).
MAX_COORD_MM = 1e7
#: A transform scales lengths by at least MIN_SCALE and at most MAX_SCALE.
MIN_SCALE, MAX_SCALE = 1e-6, 1e6
#: Smallest and largest pupil diameter, mm (an eye's is 1.5 to 9; optical instruments stay below 20).
#: Below 0.01 mm the geometric optics of the thin-lens eye no longer holds (the Airy disk of a 10 um
#: pupil spans 4 deg at 555 nm), and its area underflows long before the pupil reaches zero.
MIN_PUPIL_MM, MAX_PUPIL_MM = 0.01, 20.0
#: Largest eye focal length, mm (an eye's is 17).
MAX_FOCAL_MM = 1000.0
#: Largest accommodation distance, mm (beyond it, give "infinity").
MAX_DISTANCE_MM = 1e12
#: Nearest accommodation distance, mm: 100 dioptres, seven times the accommodation of the youngest eye
#: (about 14 D at age 10; Duane 1922, doi:10.1001/archopht.1922.00830020010002). Nearer than the pupil's
#: radius the rays to the focused point graze the pupil plane and every pixel's extent vanishes.
MIN_DISTANCE_MM = 10.0
#: Most retina pixels (4096 x 4096).
MAX_PIXELS = 1 << 24
#: Memory a render takes per retina pixel in the process that merges the batches and writes the outputs,
#: bytes (the film's sums, the image, its variance, the preview and the EXR's planes; measured by
#: benchmarks/budget.py, see docs/results/speed.md).
BYTES_PER_PIXEL = 400
#: Memory per retina pixel of a worker process, bytes: its pixels' extents and pass order; a batch's
#: film is as large as its samples, not the image.
WORKER_BYTES_PER_PIXEL = 32
#: Memory a render's process takes besides its film, bytes: the interpreter, numpy, Embree, the tracer,
#: the scene and a bounce's arrays (peaks less the film, `/usr/bin/time -v hud-trace render PRESET
#: --method backward --rays 3000000 --workers 1`: 115 MiB on analytic-mirror, 195 MiB on hud-direct
#: with next-event estimation); a worker process holds as much again.
PROCESS_BASE_BYTES = 128 << 20


def physical_memory_bytes() -> int | None:
    """This machine's physical memory (None where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, OSError, ValueError):
        return None


def available_cpus() -> int:
    """CPUs this process may run on (its affinity where the system says, else the machine's count): the
    default number of worker processes."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


class WorkersError(ValueError):
    """More worker processes than the machine's memory holds (the message says how many fit)."""


def check_workers(workers: int, resolution: tuple[int, int]) -> str | None:
    """Worker processes the machine can hold for a render of ``resolution`` (retina pixels; the largest
    of a sweep's runs): each holds the tracer, the scene and a film of its own, so together they must
    stay within half of the machine's memory (the rule of eye.resolution), or :class:`WorkersError`.
    Returns a warning where there are more workers than CPUs (they share them: more start-up time
    and memory, no more speed), else None."""
    w, h = resolution
    each = PROCESS_BASE_BYTES + w * h * WORKER_BYTES_PER_PIXEL
    parent = PROCESS_BASE_BYTES + w * h * BYTES_PER_PIXEL
    memory = physical_memory_bytes()
    if workers > 1 and memory is not None and parent + workers * each > memory / 2:
        raise WorkersError(f"{workers} processes need about {(parent + workers * each) / 2**30:.1f} GiB (each holds "
                           f"the tracer and the scene, about {each / 2**20:.0f} MiB at {w} x {h} pixels, besides the "
                           f"{parent / 2**20:.0f} MiB of the process that merges their batches); this machine has "
                           f"{memory / 2**30:.1f} GiB (the limit is half of it): at most "
                           f"{max(1, int((memory / 2 - parent) // each))} here")
    cpus = available_cpus()
    if workers > cpus:
        return (f"--workers {workers} on {cpus} CPUs: processes beyond the CPUs share them (more start-up time and "
                f"memory, no more speed)")
    return None


def _read_json_object(pairs):
    keys = [k for k, _ in pairs]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise ValueError(f"duplicate key {json.dumps(dup[0])} in one object (JSON keeps only the last)")
    return dict(pairs)


def parse_json(text: str, file: str):
    """JSON text to Python values; duplicate keys, nesting too deep for the parser and integers too
    long to read raise :class:`SceneError` naming ``file``."""
    try:
        return json.loads(text, object_pairs_hook=_read_json_object)
    except json.JSONDecodeError as e:
        raise SceneError(file, "", f"malformed JSON: {e}") from None
    except RecursionError:
        raise SceneError(file, "", "malformed JSON: nested too deeply") from None
    except ValueError as e:  # duplicate keys; an integer of more than 4300 digits
        raise SceneError(file, "", f"malformed JSON: {e}") from None


def _json_kind(value) -> str:
    """What a parsed JSON value is, in JSON's words (null, a number, a string, a list)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return json.dumps(value)
    if isinstance(value, int | float):
        return f"the number {value:g}"
    if isinstance(value, str):
        return f"the string {json.dumps(value)[:40]}"
    return "a list" if isinstance(value, list) else type(value).__name__


class FieldChecker:
    """Field validation that names the file and the JSON path of every error.

    Every method returns the validated value or raises :class:`SceneError` naming the file and the
    field (a JSON path such as ``objects[2].material.reflectance``).
    """

    def __init__(self, file: str, allow_external: bool = False):
        self.file = file
        #: Whether files named by the scene may lie outside its folder (see :meth:`path`).
        self.allow_external = allow_external

    def fail(self, fld: str, msg: str):
        raise SceneError(self.file, fld, msg)

    def obj(self, value, fld: str) -> dict:
        if not isinstance(value, dict):
            self.fail(fld, f"expected an object, got {_json_kind(value)}")
        return value

    def keys(self, d: dict, fld: str, required: set[str], optional: set[str]):
        for k in sorted(required - d.keys()):
            self.fail(f"{fld}.{k}" if fld else k, "missing required field")
        for k in sorted(d.keys() - required - optional):
            allowed = ", ".join(sorted(required | optional)) or "none"
            self.fail(f"{fld}.{k}" if fld else k, f"unknown field (allowed: {allowed})")

    def number(self, value, fld: str, *, min_value=None, min_exclusive=False, max_value=None,
               max_exclusive=False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(fld, f"expected a number, got {json.dumps(value)[:40]}")
        try:
            v = float(value)
        except OverflowError:
            self.fail(fld, f"out of range: must lie within +-{MAX_ABS:g}")
        if not math.isfinite(v):
            self.fail(fld, "must be finite")
        if min_value is not None and (v < min_value or (min_exclusive and v == min_value)):
            self.fail(fld, f"must be {'>' if min_exclusive else '>='} {min_value:g}, got {v:g}")
        if max_value is not None and (v > max_value or (max_exclusive and v == max_value)):
            self.fail(fld, f"must be {'<' if max_exclusive else '<='} {max_value:g}, got {v:g}")
        if abs(v) > MAX_ABS:
            self.fail(fld, f"out of range: must lie within +-{MAX_ABS:g}, got {v:g}")
        return v

    def vector(self, value, fld: str, n: int = 3, limit: float | None = None) -> np.ndarray:
        """A list of ``n`` numbers, each within +-``limit`` when given."""
        if not isinstance(value, list) or len(value) != n:
            self.fail(fld, f"expected a list of {n} numbers, got {json.dumps(value)[:80]}")
        lo = None if limit is None else -limit
        return np.array([self.number(v, f"{fld}[{i}]", min_value=lo, max_value=limit) for i, v in enumerate(value)])

    def path(self, root, rel, fld: str) -> Path:
        """The file ``rel`` named by the scene, which must stay inside the scene folder ``root`` (relative,
        no "..", no link out of it) unless external files are allowed: a scene folder is self-contained
        (copied, zipped for a cluster, hashed). Returns the path (not checked for existence)."""
        rel = self.string(rel, fld)
        if "\0" in rel:  # no file system takes one (os functions raise ValueError on it)
            self.fail(fld, f"{json.dumps(rel)}: a file name must not contain a NUL character")
        if self.allow_external:
            return Path(root) / rel
        p = Path(rel)
        if p.is_absolute() or p.drive or ".." in p.parts:
            self.fail(fld, f"{rel}: must be a path inside the scene folder (relative, without \"..\"); "
                           "pass --allow-external-files to allow others")
        full = Path(root) / p
        try:
            inside = Path(os.path.realpath(full)).is_relative_to(Path(os.path.realpath(root)))
        except OSError as e:
            self.fail(fld, f"{rel}: cannot be resolved ({e.strerror or e})")
        if not inside:
            self.fail(fld, f"{rel}: a link that leads out of the scene folder; pass --allow-external-files to "
                           "allow it")
        return full

    def unit_vector(self, value, fld: str) -> np.ndarray:
        v = self.vector(value, fld)
        norm = np.linalg.norm(v)
        if norm < 1e-12:
            self.fail(fld, "must not be the zero vector")
        return v / norm

    def rgb(self, value, fld: str, *, max_value: float | None = 1.0) -> np.ndarray:
        """A scalar or [r, g, b] in [0, max_value]."""
        if isinstance(value, list):
            c = self.vector(value, fld)
        else:
            c = np.full(3, self.number(value, fld))
        for i in range(3):
            if c[i] < 0 or (max_value is not None and c[i] > max_value):
                where = fld if not isinstance(value, list) else f"{fld}[{i}]"
                bounds = f"lie in [0, {max_value:g}]" if max_value is not None else "be at least 0"
                self.fail(where, f"must {bounds}, got {c[i]:g}")
        return c

    def string(self, value, fld: str) -> str:
        if not isinstance(value, str) or not value:
            self.fail(fld, f"expected a non-empty string, got {json.dumps(value)}")
        return value

    def boolean(self, value, fld: str) -> bool:
        if not isinstance(value, bool):
            self.fail(fld, f"expected true or false, got {json.dumps(value)}")
        return value
