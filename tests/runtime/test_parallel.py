"""Rendering on worker processes (tracer/runtime/parallel.py): the same image on one and two processes, also
when the tracer is a subpackage of made-up packages (as in Blender); workers that cannot start, a scene
folder that changed, external files allowed, and more workers than the memory holds refused."""

import sys
from pathlib import Path

import pytest

from tests.support.cli import assert_one_line_error, hashes, run_cli
from tests.support.paths import ROOT
from tests.support.scenes import edit_json
from tracer import cli

pytestmark = pytest.mark.serial  # worker pools with deadlines in seconds


def _wait_until_started(pool, seconds: float = 120.0):
    """Wait (at most ``seconds``) until every worker of ``pool`` has started."""
    import time

    deadline = time.monotonic() + seconds
    while pool.poll_ready() < pool.workers and time.monotonic() < deadline:
        time.sleep(0.05)


def test_more_workers_than_the_memory_holds_are_refused_and_more_than_the_cpus_warned(mirror, earlier, monkeypatch):
    """Each worker holds the tracer, the scene and its own film: --workers 1000 spawned a thousand
    processes (about 130 MiB each) on a 24 GiB machine. Workers whose memory together passes half of
    the machine's are refused in one line naming --workers, the estimate and how many fit, before any
    process starts; workers beyond the CPUs render with a warning. Here on a machine of 1 GiB: 8
    workers of analytic-mirror at 16 x 12 pixels (about 128 MiB each) and the process that merges their
    batches need 1.1 GiB."""
    import tracer.core.validate
    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime.parallel import render_parallel
    from tracer.scene import load_scene

    out, before = earlier
    monkeypatch.setattr(tracer.core.validate, "physical_memory_bytes", lambda: 1 << 30)
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 8, "--quiet", "--out", out)
    assert_one_line_error(code, err, "--workers", "8 processes need about 1.1 GiB", "16 x 12", "at most 2 here")
    assert hashes(out) == before
    with pytest.raises(tracer.core.validate.WorkersError, match="at most 2 here"):  # the library refuses them too
        render_parallel(INTEGRATORS["backward"](load_scene(mirror), 1), Budget(rays=10**12), workers=8)
    monkeypatch.setattr(tracer.core.validate, "physical_memory_bytes", lambda: 1 << 40)
    cpus = tracer.core.validate.available_cpus()
    assert cli.check_workers(cpus, (16, 12)) is None
    assert f"on {cpus} CPUs" in cli.check_workers(cpus + 1, (16, 12))


@pytest.mark.slow
@pytest.mark.parametrize("method, batch", [("forward", None), ("backward", None), ("backward", 16384)],
                         ids=["forward", "backward", "backward, batches smaller than the image"])
def test_two_processes_give_the_same_image_as_one(preset, method, batch):
    """Seed-addressed batches merged in order: the same film on one and on two processes (to the
    last bits of rounding), also where a backward batch covers a quarter of hud-direct's pixels (the
    counts per pixel equal too)."""
    from tests.support.render import films_match
    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime.parallel import render_parallel
    from tracer.scene import load_scene

    folder = preset("hud-direct")
    one = INTEGRATORS[method](load_scene(folder), 9, batch).render(Budget(rays=2_500_000))
    two = render_parallel(INTEGRATORS[method](load_scene(folder), 9, batch), Budget(rays=2_500_000), workers=2)
    assert (one.film.sample_counts() is None) == (batch is None)
    assert one.batches == two.batches and one.rays == two.rays and one.found == two.found
    assert films_match(one, two)


@pytest.mark.slow
def test_workers_start_when_the_tracer_is_a_subpackage_of_made_up_packages(preset, tmp_path):
    """Inside Blender the tracer is bl_ext.<repository>.hud_tracer.tracer, under packages Blender makes
    up at run time, which a plain interpreter cannot import. Here a copy of the tracer is imported the
    same way (an empty package "hud_made_up" over a folder that links to this checkout): its workers
    start, and the image equals the one-process render of the ordinary tracer. Its main module is
    hidden from the workers (this test process's own would be pytest's)."""
    import importlib
    import types

    from tests.support.render import films_match
    from tracer.methods import INTEGRATORS, Budget
    from tracer.scene import load_scene

    repo = tmp_path / "repo"
    repo.mkdir()
    (repo / "hud_tracer").symlink_to(ROOT, target_is_directory=True)
    made_up = types.ModuleType("hud_made_up")
    made_up.__path__ = [str(repo)]
    sys.modules["hud_made_up"] = made_up
    try:
        parallel = importlib.import_module("hud_made_up.hud_tracer.tracer.runtime.parallel")
        integrators = importlib.import_module("hud_made_up.hud_tracer.tracer.methods")
        scene_mod = importlib.import_module("hud_made_up.hud_tracer.tracer.scene")
        assert parallel._made_up_packages() == [("hud_made_up", [str(repo)])]
        folder = preset("analytic-mirror")
        previews = []
        two = parallel.render_parallel(integrators.INTEGRATORS["backward"](scene_mod.load_scene(folder), 5),
                                       integrators.Budget(rays=800_000), workers=2,
                                       preview=lambda film: previews.append(film.replicates))
        assert type(two).__module__ == "hud_made_up.hud_tracer.tracer.methods.base"
    finally:
        for name in [n for n in sys.modules if n == "hud_made_up" or n.startswith("hud_made_up.")]:
            del sys.modules[name]
    one = INTEGRATORS["backward"](load_scene(folder), 5).render(Budget(rays=800_000))
    assert one.batches == two.batches > 1 and films_match(one, two)
    # The preview saw the film while it grew (at most once a second: at least the first merge).
    assert previews and previews == sorted(previews) and previews[-1] < two.film.replicates


def test_a_worker_that_cannot_start_stops_the_render_with_its_message(preset, tmp_path):
    """A worker whose world cannot be built (its scene folder is gone) says why, and the render stops
    with that message instead of waiting for workers that the pool would start again and again (the
    parent traces meanwhile: a budget it meets alone before any worker reports ends without them)."""
    import shutil
    import time

    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime.parallel import render_parallel
    from tracer.scene import load_scene

    folder = preset("analytic-mirror")
    integrator = INTEGRATORS["backward"](load_scene(folder), 1)
    shutil.rmtree(folder)
    t0 = time.perf_counter()
    with pytest.raises(RuntimeError, match="could not start: SceneError: .*scene.json: scene file not found"):
        render_parallel(integrator, Budget(rays=10**10), workers=2)
    assert time.perf_counter() - t0 < 60


def test_workers_refuse_a_scene_folder_that_changed_since_the_render_began(preset):
    """Workers load the scene from its folder: one edited after the render began (here in the parent's
    memory, as a script might) would render another scene in them; the render stops and says so."""
    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime.parallel import render_parallel
    from tracer.scene import load_scene

    folder = preset("analytic-mirror")
    integrator = INTEGRATORS["backward"](load_scene(folder), 1)
    edit_json(folder, lambda d: d["eye"].update(pupil_diameter_mm=3.0))
    with pytest.raises(RuntimeError, match="another scene than the one the render began with"):
        render_parallel(integrator, Budget(rays=10**10), workers=2)


def test_workers_keep_their_integrator_for_the_same_scene_in_another_folder(preset, tmp_path, monkeypatch):
    """Blender exports every F12's scene into a new folder, and the workers built the same world and
    integrator again on each (the job's key held the folder): the second F12 was the slowest to show
    pixels. The key is what the batches trace: the same scene elsewhere keeps the workers' integrator;
    an edited one, or another seed, does not."""
    import shutil

    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime import parallel
    from tracer.scene import load_scene

    monkeypatch.setattr(parallel, "_WORKER", {})
    folder = preset("analytic-mirror")
    copy = shutil.copytree(folder, tmp_path / "copy")

    def job(where, seed=1):
        local = INTEGRATORS["backward"](load_scene(where), seed, 4096)
        local.prepare(Budget(rays=10**6))
        return parallel.job_of(local)

    first = job(folder)
    built = parallel._job_integrator(first)
    again = job(copy)
    assert again[0] == first[0] and again[1] != first[1]
    assert parallel._job_integrator(again) is built
    assert job(copy, seed=2)[0] != first[0]
    edit_json(copy, lambda d: d["eye"].update(pupil_diameter_mm=3.0))
    assert job(copy)[0] != first[0]


def test_external_files_are_allowed_in_the_workers_too(preset, tmp_path):
    """--allow-external-files with two workers: the workers load the folder with the same rule."""
    from tracer.cli import main

    folder = preset("analytic-mirror")
    outside = tmp_path / "meshes-outside"
    (folder / "meshes").rename(outside)
    edit_json(folder, lambda d: [o.update(mesh=str(outside / Path(o["mesh"]).name)) for o in d["objects"]])
    assert main(["render", str(folder), "--rays", "200000", "--workers", "2", "--out", str(tmp_path / "o"),
                 "--quiet", "--allow-external-files"]) == 0


def test_one_pool_serves_the_renders_of_a_session(preset):
    """Issue 31: every F12 started its worker processes again (2.8 to 4.8 s in Blender). The session's
    pool is kept: a second render, of another scene and method, reuses its processes (the same pids,
    ``pool: reused``, no start-up), gives the same image as one process, and a pool of another size
    replaces it; close_shared_pool ends the processes."""
    from tests.support.render import films_match
    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime import parallel
    from tracer.scene import load_scene

    parallel.close_shared_pool()
    first = parallel.render_parallel(INTEGRATORS["backward"](load_scene(preset("analytic-mirror")), 3),
                                     Budget(rays=20_000_000), workers=2)
    pool = parallel.shared_pool(2)
    pids = {p.pid for p in pool.pool._pool}
    assert first.extra["pool"] == "started" and pool.used
    folder = preset("analytic-disk")
    second = parallel.render_parallel(INTEGRATORS["forward"](load_scene(folder), 4), Budget(rays=3_000_000),
                                      workers=2)
    assert second.extra["pool"] == "reused" and second.extra["startup_seconds"] == 0.0
    assert parallel.shared_pool(2) is pool and {p.pid for p in pool.pool._pool} == pids
    alone = INTEGRATORS["forward"](load_scene(folder), 4).render(Budget(rays=3_000_000))
    assert films_match(alone, second)
    processes = list(pool.pool._pool)
    parallel.close_shared_pool()
    assert all(p.exitcode is not None for p in processes)


def test_a_stop_signal_that_reaches_a_closing_pools_worker_late_loses_no_batch():
    """A stop signal to the process group reaches the workers too, and a worker inside a long C call
    runs its handler late: after the parent, stopped by the same signal, has closed the pool. The
    worker ended itself then (its SIGTERM meant "the end" once the pool was closing), mid-batch; the
    pool started another and its join waited forever for the lost batch (3 in 25 group SIGTERMs
    mid-render hung). A closing pool's workers now finish their batches and end on the pool's
    sentinel: the same processes, every batch's result, and the join returns."""
    import os
    import signal
    import threading
    import time

    from tracer.runtime.parallel import WorkerPool

    pool = WorkerPool(2)
    try:
        _wait_until_started(pool)
        assert pool.ready == 2
        pids = {p.pid for p in pool.pool._pool}
        pool.used = True
        batches = [pool.pool.apply_async(time.sleep, (1.0,)) for _ in range(4)]  # two each, in a C call
        time.sleep(0.3)
        pool.close(wait=False)
        for pid in pids:  # the group's signal, landing after the close
            os.kill(pid, signal.SIGTERM)
        joined = threading.Thread(target=pool.pool.join, daemon=True)
        joined.start()
        joined.join(timeout=30)
        assert not joined.is_alive(), "the closing pool's join hung: a batch was lost"
        assert all(b.ready() and b.successful() for b in batches)
        assert {p.pid for p in pool.pool._pool} <= pids  # no worker was replaced
    finally:
        for p in pool.pool._pool:
            if p.exitcode is None:
                p.kill()


PARENT_DIES = """
import os, signal, sys, time
sys.path.insert(0, {root!r})
from tracer.runtime.parallel import WorkerPool

pool = WorkerPool(2)
while pool.poll_ready() < 2:
    time.sleep(0.05)
pool.used = True
batches = [pool.pool.apply_async(time.sleep, (120.0,)) for _ in range(2)]
time.sleep(0.5)  # both workers inside their batch
with open({pids!r}, "w") as f:  # not stdout: the orphans would hold the pipe
    f.write(" ".join(str(p.pid) for p in pool.pool._pool))
os.kill(os.getpid(), signal.SIGKILL)
"""


def _running(pid: int) -> bool:
    """Whether process ``pid`` still runs as a pool worker (a zombie, ended but not yet reaped, does not; nor
    does another process that took its number since)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            running = f.read().rsplit(")", 1)[1].split()[0] != "Z"
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return running and b"spawn_main" in f.read()
    except (FileNotFoundError, ProcessLookupError):
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process states from /proc")
def test_workers_end_with_their_parent_however_it_ended(tmp_path):
    """A worker outlived its parent: inside a batch until the batch was done, and for ever when the parent
    died holding the task queue's lock (what Blender's exit left in the add-on's tests: an orphan that held
    the test's pipe, which then waited 600 s). Killed with SIGKILL, whose end no handler sees, while both
    workers are inside a 120 s batch, the parent's workers end within seconds."""
    import os
    import subprocess
    import time

    script = tmp_path / "parent.py"
    script.write_text(PARENT_DIES.format(root=str(ROOT), pids=str(tmp_path / "pids")))
    proc = subprocess.run([sys.executable, str(script)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                          timeout=120)
    pids = [int(x) for x in (tmp_path / "pids").read_text().split()]
    assert proc.returncode == -9 and len(pids) == 2
    deadline = time.monotonic() + 10
    while any(map(_running, pids)) and time.monotonic() < deadline:
        time.sleep(0.1)
    alive = [pid for pid in pids if _running(pid)]
    for pid in alive:
        os.kill(pid, 9)
    assert not alive, f"workers {alive} outlived their parent"


def test_a_closed_pool_joins_even_when_a_worker_hangs():
    """A closed pool's join waited forever for a worker that never took its sentinel (one blocked for
    good on the task queue's lock after its sibling ended: Blender's exit in the add-on's tests, 600 s).
    With every batch back, the workers get JOIN_GRACE seconds to exit and are then killed: a worker
    stopped with SIGSTOP no longer holds the join up."""
    import os
    import signal
    import threading
    import time

    from tracer.runtime.parallel import JOIN_GRACE, WorkerPool

    pool = WorkerPool(2)
    try:
        _wait_until_started(pool)
        pool.used = True
        assert all(b.get(timeout=60) is None for b in [pool.pool.apply_async(time.sleep, (0.01,)) for _ in range(4)])
        os.kill(pool.pool._pool[0].pid, signal.SIGSTOP)
        t0 = time.monotonic()
        closing = threading.Thread(target=pool.close, daemon=True)
        closing.start()
        closing.join(timeout=60)
        assert not closing.is_alive(), "the closed pool's join waited for the stopped worker"
        assert time.monotonic() - t0 < JOIN_GRACE + 20
        assert all(p.exitcode is not None for p in pool.pool._pool)
    finally:
        for p in pool.pool._pool:
            if p.exitcode is None:
                p.kill()


def test_the_workers_abandon_the_batches_of_a_render_that_ended(mirror):
    """Issue 31: the batches still out when a render's budget was met were traced to their end by the
    workers, then dropped: 0.8 s of a core after a 2 s render at 4K, taken from the parent writing the
    outputs (and from the next F12's first batches in Blender). They are abandoned at their next bounce
    now. A render of forward batches of 2,000,000 particles met by its first batch leaves three out
    (two per worker); closing the pool, which waits for every batch handed out, took one more batch's
    time."""
    import time

    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime.parallel import close_shared_pool, render_parallel, shared_pool
    from tracer.scene import load_scene

    close_shared_pool()
    pool = shared_pool(2)
    _wait_until_started(pool)
    integrator = INTEGRATORS["forward"](load_scene(mirror), 1, 2_000_000)
    result = render_parallel(integrator, Budget(rays=1), 2)
    t0 = time.monotonic()
    close_shared_pool()
    closing = time.monotonic() - t0
    assert result.batches == 1 and result.rays > 1_000_000
    assert closing < 0.5 * result.seconds, (closing, result.seconds)


def test_a_terminated_pool_is_waited_for_a_bounded_time_even_when_a_worker_hangs():
    """Pool.terminate() joins every worker without a time limit: Blender's unregister hung in it on a worker
    blocked on the task queue's lock, which its sibling, ended by the terminate, held. A terminate now runs
    in a thread that the pool's join waits for JOIN_GRACE, then kills the workers: a worker stopped with
    SIGSTOP (which its SIGTERM cannot end) no longer holds it up."""
    import os
    import signal
    import threading
    import time

    from tracer.runtime.parallel import JOIN_GRACE, WorkerPool

    pool = WorkerPool(2)
    try:
        _wait_until_started(pool)
        os.kill(pool.pool._pool[0].pid, signal.SIGSTOP)
        t0 = time.monotonic()
        closing = threading.Thread(target=pool.close, kwargs={"terminate": True}, daemon=True)
        closing.start()
        closing.join(timeout=60)
        assert not closing.is_alive(), "the terminate waited for the stopped worker"
        assert time.monotonic() - t0 < 2 * JOIN_GRACE + 20
        assert all(p.exitcode is not None for p in pool.pool._pool)
    finally:
        for p in pool.pool._pool:
            if p.exitcode is None:
                p.kill()
