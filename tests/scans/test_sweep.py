"""Parameter sweeps (tracer.scans.sweep, ``hud-trace sweep``): an emitter's luminance swept on analytic-mirror
against the closed form L R (per run, and the recommended interval at a threshold), a requirement no
run meets, a two-field grid, the CSV round trip, the chart's threshold lines and shading found in its
pixels, Ctrl-C, a failed write, and every refusal before any ray."""

import contextlib
import io
import itertools
import json
import math
import os
import shutil
import signal

import numpy as np
import pytest

import tracer.scans.sweep as sweep_module
from presets import analytic_mirror
from tests.support.scenes import edit_json
from tests.support.stats import t_bound, z_bound
from tracer import cli
from tracer.core.imageio import read_image
from tracer.products.charts import SHADE, THRESHOLD
from tracer.scans.fields import MAX_RUNS
from tracer.scans.plan import check_arguments, plan_sweep
from tracer.scans.results import read_csv

L, R = analytic_mirror.L, analytic_mirror.R
PANEL = "objects[panel].emission.luminance"
RAYS = 200_000


def run_cli(*args):
    """``hud-trace`` in this process: (exit status, stderr)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = cli.main([str(a) for a in args])
    return code, err.getvalue()


def sweep(out, *args):
    return run_cli("sweep", *args, "--rays", RAYS, "--seed", 1, "--workers", 1, "--out", out, "--quiet")


def load(out):
    return json.loads((out / "sweep.json").read_text())


@pytest.fixture(scope="module")
def linear(tmp_path_factory):
    """L from 500 to 1500 cd/m^2 in 5 runs, with luminance.max >= 600 (closed form: L >= 600 / R)."""
    out = tmp_path_factory.mktemp("linear") / "sweep"
    code, err = sweep(out, "analytic-mirror", "--set", f"{PANEL}=500:1500:5", "--require", "luminance.max >= 600")
    return out, code, err


@pytest.fixture(scope="module")
def geometric(tmp_path_factory):
    """L from 200 to 3200 cd/m^2 in 5 geometric runs (a factor 2 apart), the same requirement."""
    out = tmp_path_factory.mktemp("log") / "sweep"
    code, err = sweep(out, "analytic-mirror", "--set", f"{PANEL}=200:3200:5", "--log", PANEL,
                      "--require", "luminance.max >= 600")
    return out, code, err


def test_each_run_reads_the_closed_form_of_its_luminance(linear):
    """Every run renders its own L: the panel seen in the mirror reads L R (the brightness-theorem
    section's rendered mean within its reported error, Sidak-corrected over the runs), and with the
    same seed the whole image scales with L (the same noise pattern: the image mean over L agrees to
    rounding, far inside the reported errors)."""
    out, code, err = linear
    assert code == 0, err
    summary = load(out)
    runs = summary["runs"]
    assert [r["values"][PANEL] for r in runs] == [500.0, 750.0, 1000.0, 1250.0, 1500.0]
    z = z_bound(len(runs))
    ratio = []
    for r in runs:
        report = json.loads((out / r["folder"] / "report.json").read_text())
        assert report["run_id"] == r["run_id"] and report["seed"] == 1 and report["partial"] is False
        lum = r["values"][PANEL]
        image = report["brightness_theorem"]["image"]
        assert abs(image["rendered_cd_m2"] - lum * R) <= z * image["standard_error_cd_m2"], (lum, image)
        mean = report["luminance"]["mean"]
        # The image mean's error comes from the spread of the run's replicates (Student-t).
        assert abs(mean / lum - runs[0]["figures"]["luminance.mean"] / 500.0) * lum <= \
            t_bound(len(runs), report["replicates"] - 1) * report["luminance"]["mean_standard_error"]
        ratio.append(mean / lum)
        assert sorted(p.name for p in (out / r["folder"]).iterdir()) == ["image.exr", "preview.png", "report.json"]
    assert np.ptp(ratio) <= 1e-9 * np.mean(ratio)  # the same seed: differences come from L alone
    assert sorted(p.name for p in (out / "runs").iterdir()) == ["0", "1", "2", "3", "4"]
    assert sorted(p.name for p in out.iterdir()) == ["runs", "sweep.csv", "sweep.json", "sweep.png"]


def _edge_tolerance(summary, run_index, x):
    """How far noise can move an edge at parameter ``x``: the maximum pixel sits a few standard errors
    above L R (10 x the median relative standard error of a lit pixel, for the ~3000 pixels)."""
    noise = summary["runs"][run_index]["figures"]["noise.median_relative_standard_error_lit_pixels"]
    return 10 * noise * x


def test_the_recommended_interval_is_the_closed_form_for_a_linear_sweep(linear):
    """luminance.max = L R is linear in L: interpolated linearly between the runs at 500 and 750 cd/m^2,
    the interval's lower edge is 600 / R = 705.9 cd/m^2 to within the noise of the maximum (a log
    interpolation would put it 7.7 cd/m^2 lower); the upper edge is the sweep's last value, open."""
    out, code, err = linear
    summary = load(out)
    rec = summary["recommendation"]
    assert rec["none"] is False and rec["runs"] == [1, 2, 3, 4]
    (iv,) = rec["intervals"]
    low, high = iv["low"], iv["high"]
    assert low["interpolated"] and low["between_runs"] == [0, 1] and low["limited_by"] == "luminance.max >= 600"
    assert abs(low["value"] - 600 / R) <= _edge_tolerance(summary, 1, 600 / R), low
    assert high["open"] and iv["to"] == 1500.0
    # The same number from the runs' own figures in the CSV: the interpolation itself.
    rows = read_csv(out / "sweep.csv")
    f0, f1 = rows[0]["luminance.max"], rows[1]["luminance.max"]
    assert low["value"] == pytest.approx(500 + (600 - f0) / (f1 - f0) * 250, rel=1e-12)
    assert "705" in err and "1500 or more" in err


def test_the_recommended_interval_is_log_interpolated_for_a_log_sweep(geometric):
    """Geometric values 200 ... 3200: the edge between the runs at 400 and 800 cd/m^2 is interpolated in
    log L. For the closed form L R that puts it at 400 x 2^t, t = (600 - 400 R) / (800 R - 400 R), 679.5
    cd/m^2: one step's interpolation error below 600 / R = 705.9 (within the step, as promised), and
    the render's edge is that point to within the noise of the maximum."""
    out, code, err = geometric
    assert code == 0, err
    summary = load(out)
    assert [r["values"][PANEL] for r in summary["runs"]] == pytest.approx([200, 400, 800, 1600, 3200], rel=1e-12)
    assert summary["grid"]["fields"][0]["scale"] == "log"
    (iv,) = summary["recommendation"]["intervals"]
    low = iv["low"]
    assert low["between_runs"] == [1, 2]
    t = (600 - 400 * R) / (800 * R - 400 * R)
    closed = 400 * 2**t
    assert 400 < closed < 800 and abs(closed - 600 / R) < 400  # within one step of the true edge
    assert abs(low["value"] - closed) <= _edge_tolerance(summary, 2, closed), (low, closed)
    assert abs(low["value"] - 600 / R) > 20  # log, not linear, interpolation
    assert summary["chart"]["panels"][0]["x"]["log"] is True


def test_the_csv_round_trips_the_runs_figures(linear):
    out, _, _ = linear
    summary = load(out)
    rows = read_csv(out / "sweep.csv")
    head = (out / "sweep.csv").read_text().splitlines()[0].split(",")
    assert head[:2] == ["run", PANEL] and head[-2:] == ["partial", "meets_requirements"]
    for col in ("hud.display_cd_m2", "luminance.mean", "luminance.max", "luminance.mean_standard_error",
                "adaptation_luminance", "noise.median_relative_standard_error_lit_pixels", "rays", "seconds",
                "efficiency"):
        assert col in head, col
    assert len(rows) == len(summary["runs"]) == 5
    for row, run in zip(rows, summary["runs"], strict=True):
        assert row["run"] == run["run"] and row[PANEL] == run["values"][PANEL]
        assert {k: v for k, v in row.items() if k in run["figures"]} == run["figures"]
        assert {k for k, v in row.items() if v is not None} - set(run["figures"]) == \
            {"run", PANEL, "partial", "meets_requirements"}
        assert row["meets_requirements"] == int(run["meets_requirements"]) and row["partial"] == 0
        assert isinstance(row["rays"], int)


def _groups(indices):
    """Centres of runs of consecutive integers."""
    out, start = [], None
    for i, k in enumerate(indices):
        if start is None:
            start = k
        if i + 1 == len(indices) or indices[i + 1] != k + 1:
            out.append((start + k) / 2)
            start = None
    return out


def _rgb(hex_colour: str) -> np.ndarray:
    return np.array([int(hex_colour[k:k + 2], 16) for k in (1, 3, 5)])


def test_the_chart_draws_the_threshold_where_its_axis_puts_it_and_shades_the_interval(linear):
    """In sweep.png: the tick marks left of the plot box, found in the pixels, give the rows of the
    y axis' tick values; the dashed red line lies at the row they interpolate for 600 cd/m^2; the
    shading starts at the column that the x axis' tick marks, under the box, interpolate for the
    interval's edge and runs to the sweep's end."""
    out, _, _ = linear
    summary = load(out)
    png = np.rint(read_image(out / "sweep.png", linear=True) * 255).astype(np.uint8)
    assert png.shape[:2] == (summary["chart"]["height"], summary["chart"]["width"])
    (panel,) = summary["chart"]["panels"]
    assert panel["key"] == "luminance.max"
    top, left, h, w = panel["box"]
    dark = png.max(axis=-1) < 120
    tick_rows = _groups(list(np.flatnonzero(dark[top:top + h + 1, left - 3]) + top))  # top to bottom
    values = [t["value"] for t in panel["y"]["ticks"]]  # ascending
    assert len(tick_rows) == len(values) >= 3
    red = np.all(np.abs(png[top:top + h, left:left + w].astype(int) - _rgb(THRESHOLD)) <= 40, axis=-1)
    line_rows = _groups(list(np.flatnonzero(red.mean(axis=1) > 0.4) + top))
    assert len(line_rows) == 1
    expected = np.interp(600, values, tick_rows[::-1])
    assert abs(line_rows[0] - expected) <= 1.5, (line_rows, expected)
    # x: tick marks under the box, and the shading's first and last columns
    tick_cols = _groups(list(np.flatnonzero(dark[top + h + 3, left - 2:left + w + 3]) + left - 2))
    x_values = [t["value"] for t in panel["x"]["ticks"]]
    assert len(tick_cols) == len(x_values) >= 3
    edge = summary["recommendation"]["intervals"][0]["from"]
    shade = np.all(np.abs(png[top + 2:top + h - 2, left:left + w].astype(int) - _rgb(SHADE)) <= 3, axis=-1)
    shaded = np.flatnonzero(shade.mean(axis=0) > 0.5) + left
    assert abs(shaded.min() - np.interp(edge, x_values, tick_cols)) <= 1.5
    assert shaded.max() >= left + w - 2 - 0.05 * w  # open to the sweep's end (4 % padding)


def test_no_run_meeting_the_requirements_gives_exit_3_none_and_the_closest_run(tmp_path):
    """luminance.max >= 5000 cd/m^2 needs L >= 5882 cd/m^2; the sweep stops at 1500: exit 3, "none",
    and the closest run is the brightest, which falls 1 - 1275 / 5000 short. A KEY the reports lack
    (analytic-mirror has no symbols, so no contrast ratio) fails every run and sweep.json says why."""
    out = tmp_path / "s"
    code, err = sweep(out, "analytic-mirror", "--set", f"{PANEL}=500:1500:3", "--require", "luminance.max >= 5000",
                      "--require", "hud.contrast_ratio >= 1.5")
    assert code == 3, err
    summary = load(out)
    rec = summary["recommendation"]
    assert rec["none"] is True and rec["runs"] == [] and rec["intervals"] == []
    closest = rec["closest"]
    assert closest["run"] == 2 and closest["values"] == {PANEL: 1500.0}
    assert closest["relative_shortfall"] == pytest.approx(1 - 1500 * R / 5000, rel=1e-3)  # the missing figure: none
    for run in summary["runs"]:
        judged = {j["requirement"]: j for j in run["requirements"]}
        assert judged["hud.contrast_ratio >= 1.5"] == {
            "requirement": "hud.contrast_ratio >= 1.5", "value": None, "met": False,
            "why": "hud has no field 'contrast_ratio'"}
        assert judged["luminance.max >= 5000"]["value"] == pytest.approx(run["values"][PANEL] * R, rel=1e-3)
    assert "no run meets every requirement; closest: run 2" in err
    assert err.count("warning: --require hud.contrast_ratio >= 1.5") == 1


def test_two_fields_make_the_cartesian_product(tmp_path):
    """L x the image width (eye.resolution[0], an integer field): 2 x 3 runs, every combination in
    order, each run with its own width and its own L R; the chart has one line per L against the width
    (--x), and the grid's recommendation is the runs that meet the requirement."""
    out = tmp_path / "g"
    code, err = sweep(out, "analytic-mirror", "--set", f"{PANEL}=500:1000:2", "--set", "eye.resolution[0]=32:64:3",
                      "--x", "eye.resolution[0]", "--require", "luminance.max >= 600")
    assert code == 0, err
    summary = load(out)
    assert summary["grid"]["runs"] == 6 and "cartesian" in summary["grid"]["product"]
    expected = list(itertools.product([500.0, 1000.0], [32, 48, 64]))
    got = [(r["values"][PANEL], r["values"]["eye.resolution[0]"]) for r in summary["runs"]]
    assert got == expected and all(isinstance(w, int) for _, w in got)
    for r in summary["runs"]:
        report = json.loads((out / r["folder"] / "report.json").read_text())
        assert report["image"]["width"] == r["values"]["eye.resolution[0]"]
        image = report["brightness_theorem"]["image"]
        assert abs(image["rendered_cd_m2"] - r["values"][PANEL] * R) <= z_bound(6) * image["standard_error_cd_m2"]
    rec = summary["recommendation"]
    assert rec["runs"] == [3, 4, 5] and "intervals" not in rec
    assert summary["chart"]["x_field"] == "eye.resolution[0]" and len(summary["chart"]["series"]) == 2
    assert len(read_csv(out / "sweep.csv")) == 6


def test_an_emission_given_by_flux_takes_the_swept_luminance(tmp_path, preset):
    """Setting an emission's luminance replaces its flux (one of the two): the loader accepts the edited
    scene, and the scene of each run holds the luminance alone."""
    folder = preset("analytic-mirror")
    edit_json(folder, lambda d: d["objects"][2]["emission"].update(flux=0.05) or d["objects"][2]["emission"].pop(
        "luminance"))
    fields, reqs = check_arguments([f"{PANEL}=100:200:2"], [], [], None, [])
    plan = plan_sweep(folder, fields, reqs, tmp_path / "work")
    for k, lum in enumerate((100.0, 200.0)):
        emission = json.loads(plan.scene_text(k))["objects"][2]["emission"]
        assert emission["luminance"] == lum and "flux" not in emission
        assert plan.load(k).objects[2].emission.luminance == lum
    assert json.loads((folder / "scene.json").read_text())["objects"][2]["emission"]["flux"] == 0.05  # untouched


@pytest.fixture
def no_render(monkeypatch):
    """Counts the runs started; a refused sweep starts none."""
    started = []

    def refuse(*args, **kwargs):
        started.append(args)
        raise AssertionError("a run was started")

    monkeypatch.setattr(sweep_module, "render_scene", refuse)
    return started


@pytest.mark.parametrize("case, args, message", [
    ("bad path", ("--set", "eye.pupil.diameter_mm=2:4:2"), "eye has no field 'pupil'"),
    ("unknown last field", ("--set", "objects[panel].emission.luminanse=1:2:2"),
     "objects[2].emission.luminanse: unknown field"),
    ("glob matches nothing", ("--set", "objects[led*].emission.luminance=1:2:2"),
     "no object's name matches 'led*' (objects: mirror, pupil_image, panel)"),
    ("glob matches an object without the block", ("--set", "objects[p*].emission.luminance=1:2:2"),
     "objects[1] (object 'pupil_image', matched by 'p*') has no field 'emission'"),
    ("value out of range", ("--set", f"{PANEL}=1e11:1e13:3", "--log", PANEL),
     "the value 1e+13 (grid point 3 of 3): scene.json: objects[2].emission.luminance: must be <= 1e+12"),
    ("zero pupil", ("--set", "eye.pupil_diameter_mm=0:4:3"), "eye.pupil_diameter_mm: must be >= 0.01"),
    ("not an integer", ("--set", "methods.backward.max_depth=4:9:3"),
     "the value 6.5 (grid point 2 of 3): scene.json: methods.backward.max_depth: expected an integer"),
    ("a boolean", ("--set", "methods.backward.next_event=0:1:2"), "methods.backward.next_event"),
    ("a list", ("--set", "eye.position=0:1:2"), "eye.position is a list of 3 values: name one of them, as "
                                                 "eye.position[0]"),
    ("index out of range", ("--set", "eye.position[3]=0:1:2"), "eye.position has 3 entries: [3] is out of range"),
    ("N = 0", ("--set", f"{PANEL}=1:2:0"), "N must be >= 1 (the number of values), got 0"),
    ("N = 1 with two ends", ("--set", f"{PANEL}=1:2:1"), "START and STOP must be equal"),
    ("not START:STOP:N", ("--set", f"{PANEL}=1:2"), "expected START:STOP:N"),
    ("too many runs", ("--set", f"{PANEL}=1:2:30", "--set", "eye.pupil_diameter_mm=2:4:30"),
     f"30 x 30 = 900 runs (every combination of the fields' values), more than {MAX_RUNS}"),
    ("set twice", ("--set", f"{PANEL}=1:2:2", "--set", f"{PANEL}=3:4:2"), "is set twice"),
    ("same target twice", ("--set", f"{PANEL}=1:2:2", "--set", "objects[pan*].emission.luminance=3:4:2"),
     "objects[2].emission.luminance is set by --set objects[panel]"),
    ("log of zero", ("--set", f"{PANEL}=0:2:3", "--log", PANEL), "START and STOP must be > 0"),
    ("log of no field", ("--set", f"{PANEL}=1:2:2", "--log", "eye.pupil_diameter_mm"), "--log eye.pupil_diameter_mm: "
                                                                                       "names no --set field"),
    ("x of no field", ("--set", f"{PANEL}=1:2:2", "--x", "eye.fov_deg[0]"), "--x eye.fov_deg[0]: names no --set"),
    ("require without op", ("--set", f"{PANEL}=1:2:2", "--require", "luminance.mean 5"), "expected \"KEY OP VALUE\""),
    ("require with =", ("--set", f"{PANEL}=1:2:2", "--require", "luminance.mean = 5"), "OP '=': must be one of"),
    ("require without value", ("--set", f"{PANEL}=1:2:2", "--require", "luminance.mean >="),
     "expected \"KEY OP VALUE\""),
    ("require a word", ("--set", f"{PANEL}=1:2:2", "--require", "luminance.mean >= bright"), "VALUE must be a number"),
    ("require nan", ("--set", f"{PANEL}=1:2:2", "--require", "luminance.mean >= nan"), "VALUE must be finite"),
    ("require a bad key", ("--set", f"{PANEL}=1:2:2", "--require", "hud..x >= 1"), "KEY 'hud..x'"),
    ("require a mistyped section", ("--set", f"{PANEL}=1:2:2", "--require", "lumnance.mean >= 1"),
     "--require lumnance.mean >= 1: 'lumnance' is not a section of a run's report.json (did you mean 'luminance'?"),
    ("y of no section", ("--set", f"{PANEL}=1:2:2", "--y", "contrast_ratio"),
     "--y contrast_ratio: 'contrast_ratio' is not a section of a run's report.json (the sections are: run_id, "),
    # below a section other than hud: every run rendered and failed for want of the figure (exit 3)
    ("require a mistyped key below a section", ("--set", f"{PANEL}=1:2:2", "--require",
                                                "brightness_theorem.ghost.ratio >= 0.1"),
     "--require brightness_theorem.ghost.ratio >= 0.1: a run's report has no brightness_theorem.ghost.ratio (did "
     "you mean 'ratio_to_symbol'?)"),
    ("y of a mistyped key below a section", ("--set", f"{PANEL}=1:2:2", "--y", "luminance.maen"),
     "--y luminance.maen: a run's report has no luminance.maen (did you mean 'mean'?)"),
])
def test_every_refusal_is_one_line_before_any_run_and_writes_nothing(tmp_path, no_render, case, args, message):
    out = tmp_path / "refused"
    code, err = sweep(out, "analytic-mirror", *args)
    lines = err.strip().splitlines()
    assert code == 2, (case, err)
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], (case, err)
    assert not out.exists() and not (out / "runs").exists(), case
    assert no_render == [], case


def test_an_object_whose_name_reads_as_a_glob_is_pointed_to_its_index(tmp_path, no_render):
    """Object names in --set are globs, so "mirror[1]" (a name Blender makes easily) matched nothing and
    the refusal listed "mirror[1]" among the objects without saying why (a hand-built input): it now
    says to address the object by its index."""
    folder = analytic_mirror.write(tmp_path / "s")
    edit_json(folder, lambda d: d["objects"][2].update(name="panel[1]"))
    code, err = sweep(tmp_path / "o", str(folder), "--set", "objects[panel[1]].emission.luminance=1:2:2")
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "names are globs (*, ? and [...] match), so address it by its index, objects[2]" in err, err
    assert no_render == []


def test_a_refused_scene_or_output_folder_writes_nothing(tmp_path, no_render):
    (tmp_path / "file").write_text("x")
    for args, out, message in ((("no-such-preset", "--set", f"{PANEL}=1:2:2"), tmp_path / "a", "no-such-preset: "
                                "neither a scene folder nor a preset"),
                               (("analytic-mirror", "--set", f"{PANEL}=1:2:2"), tmp_path / "file",
                                "file: exists and is not a folder")):
        code, err = sweep(out, *args)
        assert code == 2 and len(err.strip().splitlines()) == 1 and message in err, err
    code, err = run_cli("sweep", "analytic-mirror", "--set", f"{PANEL}=1:2:2", "--rays", 0, "--out", tmp_path / "a")
    assert code == 2 and err.startswith("error: --rays: must lie in") and len(err.strip().splitlines()) == 1, err
    # With the progress bar on: checking a short grid shows none, so the refusal is still the one line.
    code, err = run_cli("sweep", "analytic-mirror", "--set", f"{PANEL}=1e11:1e13:3", "--rays", 1000, "--out",
                        tmp_path / "a")
    assert code == 2 and err.startswith("error: --set") and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "a").exists() and (tmp_path / "file").read_text() == "x"
    assert no_render == []


def test_ctrl_c_stops_the_current_run_and_writes_the_runs_done_marked_partial(tmp_path, monkeypatch):
    """SIGINT during the second run, after its first batch: that run stops as a render does (written,
    marked partial, not judged), no third run starts, and the two runs are written with the sweep's
    files: exit 130. A SIGINT before the second run's first batch ended: the sweep ends with the first
    run (the second has no estimate to write). A second SIGINT aborts: exit 5, and the folder keeps
    the earlier sweep byte for byte."""
    real = sweep_module.render_scene

    def interrupting(times, before_any_batch=False):
        def render(scene, method, budget, seed, out, progress=None, should_stop=None, **kw):
            if out.name != "1":
                return real(scene, method, budget, seed, out, progress=progress, should_stop=should_stop, **kw)
            sent = []

            def interrupt(*_):
                if not sent:
                    sent.append(True)
                    for _ in range(times):
                        os.kill(os.getpid(), signal.SIGINT)
            if before_any_batch:
                interrupt()
            return real(scene, method, budget, seed, out, progress=interrupt, should_stop=should_stop, **kw)
        return render

    out = tmp_path / "early"
    monkeypatch.setattr(sweep_module, "render_scene", interrupting(1, before_any_batch=True))
    code, err = sweep(out, "analytic-mirror", "--set", f"{PANEL}=500:1500:4")
    assert code == 130, err
    summary = load(out)
    assert summary["partial"] is True and summary["runs_done"] == 1
    assert sorted(p.name for p in (out / "runs").iterdir()) == ["0"]

    out = tmp_path / "s"
    monkeypatch.setattr(sweep_module, "render_scene", interrupting(1))
    code, err = sweep(out, "analytic-mirror", "--set", f"{PANEL}=500:1500:4", "--require", "luminance.max >= 600",
                      "--batch-size", 8192)  # several batches per run: the stop comes after the first
    assert code == 130, err
    summary = load(out)
    assert summary["partial"] is True and summary["runs_done"] == 2
    assert [r["partial"] for r in summary["runs"]] == [False, True]
    assert json.loads((out / "runs" / "1" / "report.json").read_text())["partial"] is True
    assert sorted(p.name for p in (out / "runs").iterdir()) == ["0", "1"]
    assert summary["recommendation"]["runs"] == []  # run 0 fails, run 1 is not judged
    assert [r["partial"] for r in read_csv(out / "sweep.csv")] == [0, 1]
    assert "stopped early, not judged" in err and "Traceback" not in err

    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    monkeypatch.setattr(sweep_module, "render_scene", interrupting(2))
    code, err = sweep(out, "analytic-mirror", "--set", f"{PANEL}=500:1500:3", "--batch-size", 8192)
    assert code == 5, err
    assert err.strip().splitlines()[-1].startswith("aborted: nothing written")
    assert {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_a_new_sweep_replaces_the_earlier_runs_and_a_failed_write_keeps_them(linear, tmp_path, monkeypatch):
    """A 2-run sweep into a folder holding a 5-run sweep leaves runs 0 and 1 only (no stale runs mixed
    in); when the sweep's files cannot be written, the earlier sweep stays whole (exit 4)."""
    out = tmp_path / "s"
    shutil.copytree(linear[0], out)
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}

    commit = sweep_module.OutputSet.commit

    def failing(self, files):
        if "sweep.json" in self.names:
            raise sweep_module.OutputWriteError(self.folder, "the disk is full (test); the earlier outputs are kept")
        return commit(self, files)

    monkeypatch.setattr(sweep_module.OutputSet, "commit", failing)
    code, err = sweep(out, "analytic-mirror", "--set", f"{PANEL}=100:200:2")
    assert code == 4, err
    assert {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert sorted(p.name for p in out.iterdir()) == ["runs", "sweep.csv", "sweep.json", "sweep.png"]

    monkeypatch.setattr(sweep_module.OutputSet, "commit", commit)
    code, err = sweep(out, "analytic-mirror", "--set", f"{PANEL}=100:200:2")
    assert code == 0, err
    assert sorted(p.name for p in (out / "runs").iterdir()) == ["0", "1"]
    summary = load(out)
    assert [json.loads((out / r["folder"] / "report.json").read_text())["run_id"] for r in summary["runs"]] == \
        [r["run_id"] for r in summary["runs"]]
    assert math.isclose(summary["runs"][1]["values"][PANEL], 200.0)


@pytest.mark.slow
def test_a_sweep_says_which_runs_were_judged_on_noise(tmp_path):
    """hud-direct by forward tracing at 200,000 rays: the lit pixels' median relative error is about 1,
    and each run's line is followed by a warning that names it (before: only in sweep.json)."""
    from tests.support.cli import run_cli

    code, err = run_cli("sweep", "hud-direct", "--method", "forward", "--rays", "200000", "--workers", "1", "--set",
                        "objects[led_?].emission.luminance=1e8:1e9:2", "--quiet", "--out", tmp_path / "s")
    assert code == 0, err
    for k in (0, 1):
        assert f"warning: run {k}: judged on a noisy image" in err, err
