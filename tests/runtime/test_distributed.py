"""Rendering on a Dask cluster (tracer/runtime/distributed.py): the same image as one process."""

import pytest

pytestmark = pytest.mark.slow


def test_dask_cluster_gives_the_same_image(preset):
    """The same seed-addressed batches on a Dask LocalCluster merge to the local image."""
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
    assert dask.batches == one.batches and films_match(one, dask)
