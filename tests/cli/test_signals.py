"""Stopping ``hud-trace render`` (tracer/cli.py): Ctrl-C, SIGTERM and SIGHUP save a partial output set
promptly (exit 130); a second Ctrl-C aborts with exit 5 and one line, nothing written, the earlier set
kept, and never leaves a traceback or a mixed set."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from tests.support.cli import assert_complete_set, hashes, run_cli
from tests.support.paths import ROOT
from tracer import cli
from tracer.core.imageio import read_exr_channels


def _start(scene, out, *extra):
    proc = subprocess.Popen([sys.executable, "-m", "tracer.cli", "render", str(scene), "--seconds", "300",
                             "--out", str(out), *extra], cwd=ROOT, stderr=subprocess.PIPE, text=True)
    line = proc.stderr.readline()  # the progress bar's first line: the render is under way
    assert line.startswith("["), line
    time.sleep(1.0)
    return proc


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["INT", "TERM", "HUP"])
def test_a_stop_signal_saves_a_partial_result_promptly(mirror, tmp_path, sig):
    """SIGINT, SIGTERM and SIGHUP (what batch schedulers send) stop the render within seconds with a
    complete partial set, exit 130, and no worker prints a BrokenPipe traceback (they had killed the
    render with nothing saved, and a Ctrl-C took 5-7 s). Two workers here."""
    out = tmp_path / "o"
    proc = _start(mirror, out, "--workers", "2")
    t0 = time.monotonic()
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    waited = time.monotonic() - t0
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    report = assert_complete_set(out)
    assert report["partial"] is True and report["rays"] > 0
    assert waited < 20, waited  # a hang guard, not a measurement of the time


def test_a_second_ctrl_c_aborts_with_its_own_status_and_one_line(mirror, earlier, monkeypatch):
    """Two interrupts during a render (sent by the progress callback, so that they arrive while rays
    are traced): exit 5, one line, the earlier outputs kept. It was a KeyboardInterrupt traceback with
    the status of a saved partial result."""
    out, before = earlier
    sent = []

    class Interrupting:
        def __call__(self, fraction, message):
            if not sent:
                sent.append(True)
                os.kill(os.getpid(), signal.SIGINT)
                os.kill(os.getpid(), signal.SIGINT)

        def close(self):
            pass

    monkeypatch.setattr(cli, "ProgressBar", Interrupting)
    code, err = run_cli("render", mirror, "--seconds", 60, "--workers", 1, "--out", out)
    assert sent and code == 5, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert err.strip().splitlines()[-1].startswith("aborted: nothing written")
    assert hashes(out) == before


@pytest.mark.slow
def test_a_second_ctrl_c_from_outside_never_leaves_a_traceback_or_a_mixed_set(mirror, earlier):
    """The same from outside, with two workers: depending on when the second signal lands, the render
    aborts (exit 5, the earlier set kept) or has already written its partial set."""
    out, before = earlier
    proc = _start(mirror, out, "--workers", "2")
    proc.send_signal(signal.SIGINT)
    time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    if proc.returncode == 5:
        assert err.strip().splitlines()[-1].startswith("aborted: nothing written")
        assert hashes(out) == before
    else:  # 130, or killed by the second SIGINT while the interpreter exits after writing
        assert proc.returncode in (130, -signal.SIGINT), err
        assert assert_complete_set(out)["partial"] is True


@pytest.mark.slow
def test_ctrl_c_writes_a_partial_result(tmp_path):
    import signal
    import time

    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-m", "tracer.cli", "render", "analytic-mirror", "--method", "forward",
                             "--seconds", "120", "--out", str(out)], cwd=ROOT, stderr=subprocess.PIPE, text=True)
    time.sleep(6)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    report = json.loads((out / "report.json").read_text())
    assert report["partial"] is True and report["seconds"] < 60 and report["rays"] > 0
    ch, attrs = read_exr_channels(out / "image.exr")
    assert attrs["hud:partial"] == 1 and all(np.all(np.isfinite(c)) for c in ch.values())
