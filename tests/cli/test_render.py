"""``hud-trace render`` (tracer/cli.py): a render of hud-direct writes image.exr, preview.png and
report.json, and its arguments: each bad one refused in one line that names it, a ray budget in any
notation of a whole number, a misspelt option named before a missing required one."""

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.support.cli import assert_one_line_error, hashes, hud_trace, run_cli
from tests.support.paths import ROOT
from tracer.core.imageio import read_exr_channels

BAD_ARGS = {
    "--seed -1": (("--seed", -1), "--seed"),
    "--seed 2^64": (("--seed", 2**64), "--seed"),
    "--batch-size -1": (("--batch-size", -1), "--batch-size"),
    "--batch-size 0": (("--batch-size", 0), "--batch-size"),
    "--batch-size 1": (("--batch-size", 1), "--batch-size"),
    "--batch-size 1e12": (("--batch-size", 10**12), "--batch-size"),
    "--workers 0": (("--workers", 0), "--workers"),
    "--workers -3": (("--workers", -3), "--workers"),
    "--seconds nan": (("--seconds", "nan"), "--seconds"),
    "--seconds inf": (("--seconds", "inf"), "--seconds"),
    "--seconds 0": (("--seconds", 0), "--seconds"),
    "--rays 0": (("--rays", 0), "--rays"),
}


@pytest.mark.parametrize("case", sorted(BAD_ARGS))
def test_bad_arguments_give_one_line_naming_the_argument(mirror, earlier, case):
    """Each bad argument is refused in one line naming it, before any ray, the earlier outputs untouched
    (they were tracebacks, a NaN budget that rendered nothing, an infinite one that never ended, and
    ignored worker and batch counts)."""
    out, before = earlier
    args, flag = BAD_ARGS[case]
    budget = () if args[0] in ("--seconds", "--rays") else ("--rays", 1000)
    code, err = run_cli("render", mirror, *budget, *args, "--quiet", "--out", out)
    assert_one_line_error(code, err, flag)
    assert hashes(out) == before


@pytest.mark.slow
def test_render_hud_direct_writes_image_preview_report(tmp_path):
    """Backward tracing: forward tracing's symbols at 3 M rays are a sum of few heavy particles (40 %
    error), whose batch-means error is no bound to test against (tests/methods/test_agreement.py compares
    the methods with the statistics that fit them)."""
    out = tmp_path / "o"
    res = hud_trace("render", "hud-direct", "--method", "backward", "--rays", 3_000_000, "--seed", 7, "--out", out)
    assert res.returncode == 0, res.stderr
    report = json.loads((out / "report.json").read_text())
    for key in ("method", "seed", "rays", "paths", "seconds", "rays_per_second", "efficiency", "luminance",
                "adaptation_luminance", "warnings"):
        assert key in report
    assert report["rays"] >= 3_000_000 and 0 < report["efficiency"] < 1
    assert set(report["luminance"]) >= {"mean", "max", "log_average"}
    ch, attrs = read_exr_channels(out / "image.exr")
    assert set(ch) == {"R", "G", "B", "Y", "Y_var"}
    y = 0.2126 * ch["R"] + 0.7152 * ch["G"] + 0.0722 * ch["B"]
    np.testing.assert_allclose(ch["Y"], y, rtol=1e-5, atol=1e-6)
    assert all(np.all(np.isfinite(c)) for c in ch.values())
    assert attrs["hud:method"] == "backward" and attrs["hud:seed"] == "7"
    bt = report["brightness_theorem"]
    # The symbols follow the brightness theorem; the black leak is symbol / 300 (plus ghost spill).
    assert bt["symbol"]["predicted_cd_m2"] > 0
    sym = bt["symbol"]
    assert abs(sym["rendered_cd_m2"] - sym["predicted_cd_m2"]) < 4.5 * math.hypot(
        sym["standard_error_cd_m2"], sym["predicted_standard_error_cd_m2"])
    assert "ghost" in bt and bt["ghost"]["ratio_to_symbol"] > 0.3
    assert (out / "preview.png").is_file()


@pytest.mark.parametrize("text,value", [("5000000", 5_000_000), ("5e6", 5_000_000), ("5_000_000", 5_000_000),
                                        ("2.5e5", 250_000), ("2.5e-5", None), ("1.5", None), ("inf", None),
                                        ("nan", None), ("lots", None)])
def test_a_ray_budget_may_be_written_as_a_whole_number_in_any_notation(text, value):
    """--rays 5e6 was "invalid int value" although 1e8 is how the README and the benchmarks write it."""
    import argparse

    from tracer.cli import ray_count

    if value is None:
        with pytest.raises(argparse.ArgumentTypeError, match="number of rays"):
            ray_count(text)
    else:
        assert ray_count(text) == value and isinstance(ray_count(text), int)


@pytest.mark.parametrize("args,words", [
    (("render", "hud-direct", "--secs", "3", "--out", "o"), "unrecognized arguments: --secs"),
    (("sweep", "hud-direct", "--sets", "x=1:2:2", "--rays", "1000", "--out", "o"), "unrecognized arguments: --sets"),
    (("render", "hud-direct", "--sec", "3"), "the following arguments are required: --out"),  # an abbreviation
])
def test_a_misspelt_option_is_named_before_a_missing_required_one(args, words, tmp_path):
    """argparse checks required options before unknown ones: `render --secs 3` said only that --rays or
    --seconds is required, which sends the user looking for the wrong mistake."""
    res = subprocess.run([sys.executable, "-m", "tracer.cli", *args], cwd=tmp_path, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and words in res.stderr, res.stderr
    assert not (tmp_path / "o").exists()


def test_version_seed_help_and_auto_naming_its_choice(tmp_path, capsys):
    """`hud-trace --version`; `--seed` says what it does; an `auto` render names the method it chose."""
    from tracer import __version__

    with pytest.raises(SystemExit) as e:
        run_cli("--version")
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"hud-trace {__version__}"
    with pytest.raises(SystemExit):
        run_cli("render", "--help")
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps its lines
    assert "--seed SEED the seed of the random streams" in text and "same image on any number of workers" in text
    code, err = run_cli("render", "analytic-mirror", "--method", "auto", "--rays", "200000", "--workers", "1",
                        "--quiet", "--out", tmp_path / "o")
    assert code == 0, err
    assert "auto (chose backward):" in err


def test_a_command_run_later_in_a_process_gets_its_whole_time_budget(mirror, tmp_path, monkeypatch):
    """--seconds count from the command's start: for the console script, the process's start (its
    imports count); for main() called by a host program or a test an hour into the process, from the
    call. It counted from the process's start there too, so such a render found its budget spent and
    stopped after one batch."""
    import time

    from tracer import cli

    monkeypatch.setattr(cli, "STARTED", time.perf_counter() - 3600.0)  # the process and its import, an hour ago
    monkeypatch.setattr(cli, "_IMPORTED", time.perf_counter() - 3600.0)
    out = tmp_path / "o"
    code, err = run_cli("render", mirror, "--seconds", 1, "--workers", 1, "--quiet", "--out", out)
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    assert 0.9 <= report["seconds"] < 30 and report["batches"] > 1, (report["seconds"], report["batches"])
