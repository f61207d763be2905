"""The command line's contract, shared by the tests of every part that refuses bad input or writes an
output set through it (docs/user/cli.md: exit 0 or 3 with a complete, finite output set; exit 2 with one
line naming the file or argument and the field, before any ray, the output folder as it was; 4 when the
outputs cannot be written, the earlier set intact; 130 for a stop signal with a partial set; 5 for an
abort, nothing written): ``hud-trace`` in this process and in a child process, the output folder's
hashes, and the checks of a one-line refusal and of a complete output set."""

from __future__ import annotations

import hashlib
import io
import json
import resource
import signal
import subprocess
import sys
from contextlib import redirect_stderr
from pathlib import Path

import numpy as np

from tests.support.paths import ROOT
from tracer import cli
from tracer.core.imageio import read_exr_channels

OUTPUTS = ("image.exr", "preview.png", "report.json")


class Hang(Exception):
    """hud-trace did not return in time."""


def _hang(signum, frame):
    raise Hang("hud-trace did not return within 120 s (a refusal that came after the first ray?)")


def run_cli(*args) -> tuple[int, str]:
    """``hud-trace`` in this process: (exit status, stderr). Budgets of 10**12 rays in the tests that
    expect a refusal make a late refusal a hang; an alarm turns it into a failure."""
    err = io.StringIO()
    previous = signal.signal(signal.SIGALRM, _hang)
    signal.alarm(120)
    try:
        with redirect_stderr(err):
            code = cli.main([str(a) for a in args])
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    return code, err.getvalue()


def hud_trace(*args, timeout=600, **kw):
    """``hud-trace`` in a child process (where C libraries' own output shows): the CompletedProcess."""
    return subprocess.run([sys.executable, "-m", "tracer.cli", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout, **kw)


def hashes(folder: Path) -> dict:
    """SHA-256 of every entry of ``folder`` (hidden ones included), by name."""
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
            for p in sorted(Path(folder).iterdir())}


def assert_one_line_error(code: int, err: str, *words: str):
    """Exit status 2 and one line on stderr, "error: ...", holding every one of ``words``."""
    assert code == 2, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    for w in words:
        assert w in lines[0], (w, err)


def assert_complete_set(out: Path) -> dict:
    """The three outputs present, finite, and of one run; returns the report."""
    report = json.loads((out / "report.json").read_text())
    ch, attrs = read_exr_channels(out / "image.exr")
    assert attrs["hud:run_id"] == report["run_id"] and attrs["hud:seed"] == str(report["seed"])
    assert all(np.all(np.isfinite(c)) for c in ch.values())
    assert (out / "preview.png").stat().st_size > 0
    assert sorted(p.name for p in out.iterdir()) == sorted(OUTPUTS)  # no staging or stray files
    return report


def limit_file_size():
    """A nearly full disk: writes beyond 1024 bytes fail (EFBIG) instead of killing the process."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (1024, resource.RLIM_INFINITY))
