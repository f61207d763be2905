"""Rendering on a Dask cluster (tracer/runtime/distributed.py): the same image as one process."""

import shutil
from pathlib import Path

import pytest

pytestmark = [pytest.mark.slow, pytest.mark.serial]  # a LocalCluster of several processes


def test_dask_cluster_gives_the_same_image(preset):
    """The same seed-addressed batches on a Dask LocalCluster merge to the local image. Each worker
    unpacks the scene inside its own local directory, which it removes when it closes (a copy of every
    scene rendered had stayed in the temp folder)."""
    distributed = pytest.importorskip("distributed")
    from tests.support.render import films_match
    from tracer.methods import INTEGRATORS, Budget
    from tracer.runtime.distributed import render_dask
    from tracer.scene import load_scene

    folder = preset("hud-direct")
    one = INTEGRATORS["forward"](load_scene(folder), 4).render(Budget(rays=2_000_000))
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    with cluster, distributed.Client(cluster) as client:
        dask = render_dask(INTEGRATORS["forward"](load_scene(folder), 4), Budget(rays=2_000_000), client)
        places = client.run(_unpacked_and_local_directory)
    assert dask.batches == one.batches and films_match(one, dask)
    assert len(places) == 2
    for unpacked, local in places.values():
        assert len(unpacked) == 1 and Path(unpacked[0]).parent == Path(local), (unpacked, local)


def _unpacked_and_local_directory(dask_worker):
    from tracer.runtime import distributed

    return list(distributed._UNPACKED.values()), dask_worker.local_directory


def test_a_worker_keeps_the_last_scenes_it_unpacked(preset, monkeypatch):
    """A long-lived worker that renders a sweep's runs keeps only the last KEEP_UNPACKED scenes it
    unpacked; a scene used again counts as the newest."""
    from tracer.runtime import distributed

    monkeypatch.setattr(distributed, "_UNPACKED", {})
    blobs = []
    for k in range(3):
        folder = preset("analytic-mirror", resolution=(4 + k, 4))
        blobs.append(distributed.pack_scene(folder))
    first = distributed.unpacked(blobs[0], "a")
    second = distributed.unpacked(blobs[1], "b")
    assert distributed.unpacked(blobs[0], "a") == first  # used again: not unpacked twice
    third = distributed.unpacked(blobs[2], "c")
    assert distributed.KEEP_UNPACKED == 2 and list(distributed._UNPACKED) == ["a", "c"]
    assert Path(first, "scene.json").is_file() and Path(third, "scene.json").is_file()
    assert not Path(second).exists()
    for folder in distributed._UNPACKED.values():
        shutil.rmtree(folder)


def test_the_command_line_renders_on_a_scheduler_the_same_image_and_set(preset, tmp_path):
    """Issue 31: `hud-trace render --scheduler ADDRESS` (a LocalCluster of two worker processes here) writes
    the same output set as a local render, and for a budget in rays the same image (to the last bits of
    rounding); its report names the scheduler and the cluster's workers. An address where no scheduler
    answers is refused before anything is loaded, in one line naming --scheduler (exit 2, nothing
    written)."""
    distributed = pytest.importorskip("distributed")
    import json

    import numpy as np

    from tests.support.cli import assert_one_line_error, run_cli
    from tracer.core.imageio import read_exr_channels

    folder = preset("hud-direct")
    local, remote = tmp_path / "local", tmp_path / "remote"
    code, err = run_cli("render", folder, "--rays", 2_000_000, "--seed", 3, "--workers", 1, "--quiet",
                        "--out", local)
    assert code == 0, err
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    with cluster:
        code, err = run_cli("render", folder, "--rays", 2_000_000, "--seed", 3, "--quiet", "--out", remote,
                            "--scheduler", cluster.scheduler_address)
    assert code == 0, err
    assert sorted(p.name for p in local.iterdir()) == sorted(p.name for p in remote.iterdir())
    a, b = read_exr_channels(local / "image.exr")[0], read_exr_channels(remote / "image.exr")[0]
    assert set(a) == set(b) and all(np.allclose(a[k], b[k], rtol=1e-6, atol=0) for k in ("R", "G", "B", "Y"))
    report = json.loads((remote / "report.json").read_text())
    assert report["workers"] == 2 and report["method_details"]["scheduler"] == cluster.scheduler_address
    assert report["rays"] == json.loads((local / "report.json").read_text())["rays"]
    code, err = run_cli("render", folder, "--rays", 1000, "--out", tmp_path / "none", "--scheduler",
                        "tcp://127.0.0.1:9")
    assert_one_line_error(code, err, "--scheduler", "tcp://127.0.0.1:9", "no Dask scheduler answers")
    assert not (tmp_path / "none").exists()


@pytest.mark.parametrize("address", ["foo", "tcp://foo", "tcp://127.0.0.1:99999", "host:port"])
def test_what_is_not_a_scheduler_address_is_named_so(address):
    """A second walk-through: `--scheduler foo` said "no Dask scheduler answers there within 10 s" at once
    (Dask's ValueError: the port was missing). Now: not an address, and what one looks like."""
    pytest.importorskip("distributed")
    from tracer.runtime.distributed import SchedulerError, connect

    with pytest.raises(SchedulerError, match="not a scheduler's address; give HOST:PORT or tcp://HOST:PORT"):
        connect(address)
