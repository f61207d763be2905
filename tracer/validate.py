"""Validation of JSON fields for the scene format: one checker for every block of scene.json."""

from __future__ import annotations

import json
import math

import numpy as np

from .errors import SceneError


class FieldChecker:
    """Field validation that names the file and the JSON path of every error.

    Every method returns the validated value or raises :class:`SceneError` naming the file and the
    field (a JSON path such as ``objects[2].material.reflectance``).
    """

    def __init__(self, file: str):
        self.file = file

    def fail(self, fld: str, msg: str):
        raise SceneError(self.file, fld, msg)

    def obj(self, value, fld: str) -> dict:
        if not isinstance(value, dict):
            self.fail(fld, f"expected an object, got {type(value).__name__}")
        return value

    def keys(self, d: dict, fld: str, required: set[str], optional: set[str]):
        for k in sorted(required - d.keys()):
            self.fail(f"{fld}.{k}" if fld else k, "missing required field")
        for k in sorted(d.keys() - required - optional):
            allowed = ", ".join(sorted(required | optional)) or "none"
            self.fail(f"{fld}.{k}" if fld else k, f"unknown field (allowed: {allowed})")

    def number(self, value, fld: str, *, min_value=None, min_exclusive=False, max_value=None) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(fld, f"expected a number, got {json.dumps(value)}")
        v = float(value)
        if not math.isfinite(v):
            self.fail(fld, "must be finite")
        if min_value is not None and (v < min_value or (min_exclusive and v == min_value)):
            self.fail(fld, f"must be {'>' if min_exclusive else '>='} {min_value}, got {v:g}")
        if max_value is not None and v > max_value:
            self.fail(fld, f"must be <= {max_value}, got {v:g}")
        return v

    def vector(self, value, fld: str, n: int = 3) -> np.ndarray:
        if not isinstance(value, list) or len(value) != n:
            self.fail(fld, f"expected a list of {n} numbers, got {json.dumps(value)}")
        return np.array([self.number(v, f"{fld}[{i}]") for i, v in enumerate(value)])

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
                self.fail(where, f"must lie in [0, {max_value}], got {c[i]:g}")
        return c

    def string(self, value, fld: str) -> str:
        if not isinstance(value, str) or not value:
            self.fail(fld, f"expected a non-empty string, got {json.dumps(value)}")
        return value

    def boolean(self, value, fld: str) -> bool:
        if not isinstance(value, bool):
            self.fail(fld, f"expected true or false, got {json.dumps(value)}")
        return value
