"""Output sets (tracer/products/outputs.py, through ``hud-trace render``): written as a set, so that a full
disk, an output name taken by a folder, concurrent renders into one folder, a folder that cannot be written,
is empty, lies in the scene or is too long, and a stop before the first batch never leave a mixed or broken
set; the earlier set stays as it was."""

import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.cli import assert_complete_set, assert_one_line_error, hashes, hud_trace, limit_file_size, run_cli
from tests.support.paths import ROOT
from tracer.methods import Budget
from tracer.scene import load_scene


def test_a_full_disk_leaves_the_earlier_set_intact(mirror, earlier):
    """A full disk: exit 4, the earlier set intact (a short write replaced a good image.exr with 4096
    unreadable bytes, exit 0)."""
    out, before = earlier
    res = hud_trace("render", mirror, "--rays", 100_000, "--workers", 1, "--quiet", "--out", out,
                    timeout=300, preexec_fn=limit_file_size)
    assert res.returncode == 4, res.stderr
    assert "Traceback" not in res.stderr and "earlier outputs" in res.stderr
    assert hashes(out) == before


def test_a_full_disk_into_an_empty_folder_leaves_nothing(mirror, tmp_path):
    out = tmp_path / "new"
    res = hud_trace("render", mirror, "--rays", 100_000, "--workers", 1, "--quiet", "--out", out,
                    timeout=300, preexec_fn=limit_file_size)
    assert res.returncode == 4 and "Traceback" not in res.stderr, res.stderr
    assert not out.exists() or list(out.iterdir()) == []


@pytest.mark.parametrize("name", ["preview.png", "report.json", "image.exr"])
def test_an_output_name_taken_by_a_folder_is_refused_before_the_render(mirror, earlier, name):
    """An output name taken by a folder is refused in one line before the render (it was a traceback
    after the new image.exr was already in place next to the old report)."""
    out, _ = earlier
    (out / name).unlink()
    (out / name).mkdir()
    before = hashes(out)
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, name, "not a file")
    assert hashes(out) == before


@pytest.mark.slow
def test_concurrent_renders_into_one_folder_never_mix(mirror, tmp_path):
    """One render holds the folder; the others are refused before tracing (six renders into one --out
    all exited 0, and the EXR and the report could come from different seeds)."""
    out = tmp_path / "out"
    procs = [subprocess.Popen([sys.executable, "-m", "tracer.cli", "render", str(mirror), "--rays", "400000",
                               "--workers", "1", "--quiet", "--seed", str(seed), "--out", str(out)], cwd=ROOT,
                              stderr=subprocess.PIPE, text=True) for seed in range(4)]
    results = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    for p in procs:
        p.stderr.close()
    codes = [c for c, _ in results]
    assert set(codes) <= {0, 2} and 0 in codes, results
    for code, err in results:
        if code == 2:
            assert "another render is writing into this folder" in err and "Traceback" not in err
    report = assert_complete_set(out)
    assert codes[report["seed"]] == 0


@pytest.mark.parametrize("where", ["a file", "under a file", "/dev/null", "/proc/x"])
def test_an_output_folder_that_cannot_be_written_is_refused_before_the_render(mirror, tmp_path, where):
    """Refused in one line before the render (it was a traceback after the whole render). The budget
    here would take days: the refusal comes first."""
    f = tmp_path / "f"
    f.write_text("x")
    out = {"a file": f, "under a file": f / "out", "/dev/null": Path("/dev/null"), "/proc/x": Path("/proc/x")}[where]
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, str(out) if where != "under a file" else str(f))
    assert f.read_text() == "x"


@pytest.mark.parametrize("where", ["empty", "the scene folder", "inside the scene folder", "a name too long"])
def test_an_output_folder_that_is_empty_or_in_the_scene_or_too_long_is_refused(mirror, tmp_path, where,
                                                                                monkeypatch):
    """An empty --out (an unset $OUT in a script) wrote into the working directory; --out in the scene
    folder mixed the outputs with the scene's files (and could overwrite an HDRI named image.exr); a
    name longer than the file system takes gave exit 4 and the raw errno. Now exit 2 before any ray,
    one line, and nothing made."""
    monkeypatch.chdir(tmp_path)
    out = {"empty": "", "the scene folder": mirror, "inside the scene folder": mirror / "renders" / "a",
           "a name too long": tmp_path / ("n" * 300)}[where]
    before = hashes(mirror), hashes(tmp_path)
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err)
    assert (hashes(mirror), hashes(tmp_path)) == before


def test_a_stop_before_the_first_batch_keeps_the_earlier_set(mirror, earlier):
    """A Ctrl-C in the first half second replaced a good earlier set with a black one of 0 rays whose
    warning blamed the scene ("none reached a source"). A render stopped before its first batch has
    nothing to write: the folder keeps its set, and the command says so with status 130. A sweep
    stopped so ends with the runs before it."""
    from tracer.core.errors import StoppedBeforeFirstBatch
    from tracer.products.render import render_scene
    from tracer.scans.sweep import open_outputs

    out, before = earlier
    with pytest.raises(StoppedBeforeFirstBatch):
        render_scene(load_scene(mirror), "backward", Budget(rays=10**6), 1, out, should_stop=lambda: True)
    assert hashes(out) == before
    with pytest.raises(Exception, match="lies in the scene folder"):
        open_outputs(mirror / "sweep", mirror)
