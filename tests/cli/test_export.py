"""``hud-trace presets`` and ``hud-trace export`` (tracer/cli.py): the presets listed in one column and
exported as scene folders; an export into a place that cannot take it refused in one line, and one onto
a full disk leaving nothing behind."""

from pathlib import Path

import pytest

from tests.support.cli import assert_one_line_error, hud_trace, limit_file_size, run_cli


@pytest.mark.slow
def test_presets_listed_and_exported(tmp_path):
    out = hud_trace("presets")
    assert out.returncode == 0
    names = [line.split()[0] for line in out.stdout.splitlines()]
    assert names == ["hud-direct", "hud-screen", "hud-screen-ideal-lcd", "hud-direct-condenser", "hud-screen-day",
                     "hud-screen-night", "hud-direct-env", "hud-direct-s", "hud-direct-s-sunglasses",
                     "hud-direct-film-sunglasses", "hud-direct-wedge", "hud-direct-curved", "analytic-mirror",
                     "analytic-disk", "analytic-furnace"]
    lines = out.stdout.splitlines()
    columns = {len(line) - len(line[len(name):].lstrip()) for name, line in zip(names, lines, strict=True)}
    assert len(columns) == 1, "every summary starts in one column"
    for name in ("hud-direct", "hud-screen", "hud-direct-condenser", "hud-direct-wedge"):
        assert hud_trace("export", name, tmp_path / name).returncode == 0
        assert (tmp_path / name / "scene.json").is_file() and (tmp_path / name / "textures" / "slide.png").is_file()


@pytest.mark.parametrize("where", ["under a file", "a file", "/dev/null", "/proc/x", "not empty"])
def test_export_into_a_place_that_cannot_take_it_gives_one_line(tmp_path, where):
    f = tmp_path / "f"
    f.write_text("x")
    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("mine")
    target = {"under a file": f / "sub", "a file": f, "/dev/null": Path("/dev/null"), "/proc/x": Path("/proc/x"),
              "not empty": full}[where]
    code, err = run_cli("export", "hud-direct", target)
    assert_one_line_error(code, err, str(target))
    assert f.read_text() == "x" and (full / "keep.txt").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f", "full"]  # no staging folder left


def test_export_on_a_full_disk_leaves_nothing(tmp_path):
    res = hud_trace("export", "hud-direct", tmp_path / "s", timeout=300, preexec_fn=limit_file_size)
    assert res.returncode == 4 and "Traceback" not in res.stderr, res.stderr
    assert list(tmp_path.iterdir()) == []
