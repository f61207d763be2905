"""What a sweep says while it runs and at its end (tracer/scans/sweep.py, tracer/scans/results.py), from a
second walk-through of issue 31: progress lines named the hidden staging folder a run is written into,
the end line of a sweep without requirements said "0 runs" of a sweep stopped in its second run, and an
interval open below read "<= 3 to 4"."""

from tracer.methods import Budget
from tracer.products.outputs import STAGING_PREFIX
from tracer.scans.plan import check_arguments, plan_sweep
from tracer.scans.sweep import open_outputs, run_sweep


def test_a_sweeps_progress_names_the_runs_folders_and_its_end_line_counts_its_runs(mirror, tmp_path):
    fields, reqs = check_arguments(["eye.pupil_diameter_mm=3:4:2"], [], [], None, [])
    plan = plan_sweep(mirror, fields, reqs, tmp_path / "work")
    said = []
    outputs = open_outputs(tmp_path / "out", mirror)
    try:
        result = run_sweep(plan, "backward", Budget(rays=200_000), 1, outputs,
                           progress=lambda fraction, message: said.append(message))
    finally:
        outputs.close()
    assert said and not any(STAGING_PREFIX in m for m in said), [m for m in said if STAGING_PREFIX in m][:1]
    assert any(str(tmp_path / "out" / "runs" / "1") in m for m in said)
    assert result.describe() == "2 runs rendered to their budget; no requirements given"
