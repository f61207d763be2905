"""Typed errors of the tracer.

Every error caused by input names the file and the field that is wrong, so that the command
line can print one clear line and exit with status 2 (see :mod:`tracer.cli`).
"""

from __future__ import annotations

import signal

#: The signals that stop a render, a sweep or a scan (Ctrl-C, a batch scheduler's time limit, a
#: terminal's hang-up), where the platform has them.
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


class TracerError(Exception):
    """Base class of every error the tracer raises on purpose."""


def one_line(text: str) -> str:
    """``text`` on one line: its non-empty lines joined by "; " (libraries' messages can span
    several, and the command line promises one line per error)."""
    return "; ".join(line.strip() for line in str(text).splitlines() if line.strip())


def printable(text: str) -> str:
    """``text`` with every non-printable character escaped ("\\r", "\\x00"): a key or value copied
    from a user's file into a message must not break its line."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(text))


class SceneError(TracerError):
    """Bad input: a scene folder, a scene.json field, a mesh or an image.

    Parameters
    ----------
    file : str
        The file at fault (a path as the user gave it, or relative to the scene folder).
    field : str
        The JSON path of the offending field (``objects[3].material.reflectance``), or ``""``
        when the whole file is at fault (malformed JSON, unreadable image).
    message : str
        What is wrong and, where it helps, what is expected.
    """

    def __init__(self, file: str, field: str, message: str):
        self.file = printable(file)
        self.field = field = printable(field)
        self.message = message = one_line(message)
        where = f"{self.file}: {field}" if field else self.file
        super().__init__(f"{where}: {message}")


class ImageReadError(TracerError):
    """An image file could not be read (missing, unreadable or of an unsupported format)."""

    def __init__(self, path: str, reason: str):
        self.path = printable(path)
        self.reason = reason = one_line(reason)
        super().__init__(f"{self.path}: {reason}")



class EstimateOverflowError(TracerError):
    """A value of the estimate does not fit the outputs (float32 images, JSON): a scene whose
    luminances or fluxes are beyond what the tracer can represent."""


class StoppedBeforeFirstBatch(TracerError):
    """A render stopped (Ctrl-C, a cancel) before its first batch ended: there is no estimate to write,
    so the output folder keeps what it held instead of taking a black image."""
