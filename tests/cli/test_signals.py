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

pytestmark = pytest.mark.serial  # stop signals to process groups, with hang guards in seconds


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


def _interrupting_bar(sent: list, interrupts: int):
    """A progress bar for cmd_render that sends this process ``interrupts`` SIGINTs at its first call
    (so that they arrive while rays are traced), and notes in ``sent`` that it did."""

    class Interrupting:
        def __call__(self, fraction, message):
            if not sent:
                sent.append(True)
                for _ in range(interrupts):
                    os.kill(os.getpid(), signal.SIGINT)

        def close(self):
            pass

    return Interrupting


def test_a_second_ctrl_c_aborts_with_its_own_status_and_one_line(mirror, earlier, monkeypatch):
    """Two interrupts during a render (sent by the progress callback, so that they arrive while rays
    are traced): exit 5, one line, the earlier outputs kept. It was a KeyboardInterrupt traceback with
    the status of a saved partial result."""
    out, before = earlier
    sent = []
    monkeypatch.setattr(cli, "ProgressBar", _interrupting_bar(sent, interrupts=2))
    code, err = run_cli("render", mirror, "--seconds", 60, "--workers", 1, "--out", out)
    assert sent and code == 5, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert err.strip().splitlines()[-1].startswith("aborted: nothing written")
    assert hashes(out) == before


def test_a_second_ctrl_c_after_the_set_is_written_says_so(mirror, earlier, monkeypatch):
    """The first interrupt stops the render; the second lands once its partial set is in place (sent here
    as the render keeps the folder it wrote). It said "aborted: nothing written; ... keeps what it held" with exit 5,
    while the folder held the new partial set (seen once from outside, in a CI run). Now: exit 130, one
    line saying the folder holds the outputs, the partial set whole."""
    from tracer.products import outputs

    out, before = earlier
    sent = []
    keep = outputs.OutputSet.keep

    def kept_then_interrupted(self):
        keep(self)
        os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(cli, "ProgressBar", _interrupting_bar(sent, interrupts=1))
    monkeypatch.setattr(outputs.OutputSet, "keep", kept_then_interrupted)
    code, err = run_cli("render", mirror, "--seconds", 60, "--workers", 1, "--out", out)
    assert sent and code == 130, err
    assert "Traceback" not in err and "nothing written" not in err
    assert err.strip().splitlines()[-1].startswith("aborted after the outputs were written")
    assert hashes(out) != before and assert_complete_set(out)["partial"] is True


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


def _children(pid: int) -> list[int]:
    """The child processes of ``pid`` (Linux's /proc)."""
    try:
        return [int(c) for c in open(f"/proc/{pid}/task/{pid}/children").read().split()]
    except OSError:
        return []


def _group_stop(args, sig, when, timeout=60):
    """Start ``hud-trace args`` in a session of its own, send ``sig`` to its whole process group (what a
    batch scheduler's time limit and a terminal's hang-up do) at ``when``: "start-up" (as soon as the
    worker processes exist, before they have built their worlds) or "mid-render" (a second after the
    first progress line). (exit status, stderr, seconds from the signal to the exit)."""
    proc = subprocess.Popen([sys.executable, "-m", "tracer.cli", *map(str, args)], cwd=ROOT, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    if when == "start-up":
        deadline = time.monotonic() + 60
        while len(_children(proc.pid)) < 3 and time.monotonic() < deadline:  # the resource tracker and 2 workers
            time.sleep(0.01)
    else:
        line = proc.stderr.readline()
        assert line.startswith("["), line
        time.sleep(1.0)
    t0 = time.monotonic()
    os.killpg(proc.pid, sig)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        raise
    return proc.returncode, err, time.monotonic() - t0


@pytest.mark.slow
@pytest.mark.parametrize("when", ["start-up", "mid-render"])
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT], ids=["TERM", "HUP", "INT"])
def test_a_stop_signal_to_the_process_group_ends_the_render(mirror, tmp_path, sig, when):
    """The signal reaches the two workers too. SIGTERM hung (the pool restarted the killed workers and
    waited for their lost batches, nothing written); Ctrl-C while the workers started gave a traceback;
    SIGHUP printed the resource tracker's KeyError tracebacks. Now: exit 130 within seconds, no
    traceback, a complete partial set mid-render, nothing written at start-up."""
    out = tmp_path / "o"
    code, err, waited = _group_stop(["render", mirror, "--seconds", "300", "--workers", "2", "--out", out], sig, when)
    assert code == 130, err
    assert "Traceback" not in err and "KeyError" not in err, err
    if when == "mid-render":
        assert assert_complete_set(out)["partial"] is True
    elif "nothing written" in err:
        assert not out.exists() or not list(out.iterdir())
    else:  # the first batch had landed already
        assert assert_complete_set(out)["partial"] is True
    assert waited < 10, waited  # a hang guard; the 2 s goal is measured, not tested


@pytest.mark.slow
def test_a_stop_signal_to_the_process_group_ends_a_sweep_with_its_runs_so_far(tmp_path):
    out = tmp_path / "s"
    code, err, waited = _group_stop(["sweep", "analytic-mirror", "--method", "forward", "--seconds", "30", "--workers",
                                     "2", "--set", "objects[panel].emission.luminance=100:200:3", "--out", out],
                                    signal.SIGTERM, "mid-render")
    assert code == 130, err
    assert "Traceback" not in err and waited < 10
    summary = json.loads((out / "sweep.json").read_text())
    assert summary["partial"] is True
    assert sorted(p.name for p in out.iterdir()) == ["runs", "sweep.csv", "sweep.json", "sweep.png"]  # no staging


@pytest.mark.parametrize("scene", ["hud-direct", "hud-screen"])
def test_a_stop_signal_ends_an_eyebox_scan_with_nothing_written(tmp_path, scene):
    """hud-screen's scan is stopped while its photon map is built (the progress bar's first lines)."""
    out = tmp_path / "e"
    proc = subprocess.Popen([sys.executable, "-m", "tracer.cli", "eyebox", scene, "--out", str(out)], cwd=ROOT,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    line = proc.stderr.readline()  # the progress bar: the scan is under way
    assert line.startswith("["), line
    os.killpg(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "nothing written" in err and "Traceback" not in err, err
    assert not out.exists() or not list(out.iterdir())


def test_a_stopped_render_keeps_its_hud_figures_marked_partial(preset, tmp_path):
    """Issue 31: a render stopped with Ctrl-C wrote a set whose hud and brightness_theorem were null, so
    the figures of what it had accumulated were lost and readouts showed only the mean. A stop after
    the first batch now keeps the HUD figures of the batches merged, marked partial (hud-direct, one
    process, stopped by should_stop after its first merge); readouts print them."""
    from tracer.methods import Budget
    from tracer.products.render import render_folder

    answers = iter([False] * 3 + [True] * 10**6)
    report, result = render_folder(preset("hud-direct"), "backward", Budget(rays=10**12), 1, tmp_path / "o",
                                   should_stop=lambda: next(answers))
    assert result.partial and report["partial"] and report["brightness_theorem"] is None
    hud = report["hud"]
    assert hud["partial"] is True and hud["symbol_cd_m2"] > 10 * hud["background_cd_m2"] > 0
    assert report["analysis"] == "hud figures only (stopped render)"
    code, err = run_cli("readouts", tmp_path / "o")
    assert code == 0


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["INT", "TERM"])
def test_a_stop_signal_while_a_sweep_checks_its_grid_ends_it_with_nothing_written(mirror, tmp_path, monkeypatch,
                                                                                  sig):
    """A second walk-through: a stop signal while a sweep loaded its grid's scenes, before its own handler,
    gave exit 5 ("aborted", a second Ctrl-C's status) for Ctrl-C, and for SIGTERM the default death (143,
    no word, the folder made for the outputs left behind). Both now say the work had not begun: 130,
    nothing written, no folder left."""
    from tracer.scans import plan

    real = plan.plan_sweep

    def signalled(*args, **kwargs):
        os.kill(os.getpid(), sig)  # the handler runs at the next bytecode: before the grid is planned
        return real(*args, **kwargs)

    monkeypatch.setattr(plan, "plan_sweep", signalled)
    before = signal.getsignal(signal.SIGTERM)
    out = tmp_path / "o"
    code, err = run_cli("sweep", mirror, "--set", "eye.pupil_diameter_mm=3:4:2", "--rays", 100_000, "--quiet",
                        "--out", out)
    assert code == 130 and "interrupted before the first run began" in err and "Traceback" not in err, err
    assert not out.exists()
    assert signal.getsignal(signal.SIGTERM) == before  # main() puts back the handler it found


def test_a_stop_signal_while_the_command_ends_its_worker_pool_is_ignored(mirror, tmp_path, monkeypatch):
    """A second Ctrl-C that landed as the command ended its worker pool, after the set was written (the
    pool's bounded join), printed a KeyboardInterrupt traceback (a fresh-clone CI run, 2026-12-07). The
    work is done there: the stop signals are ignored while the session ends."""
    from tracer.runtime import parallel

    real = parallel.close_shared_pool

    def signalled(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)  # where the handler would raise
        return real(*args, **kwargs)

    monkeypatch.setattr(parallel, "close_shared_pool", signalled)
    code, err = run_cli("render", mirror, "--rays", 100_000, "--workers", 1, "--quiet", "--out", tmp_path / "o")
    assert code == 0 and "Traceback" not in err, err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back
