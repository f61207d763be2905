"""Fixtures shared by the test files: scene folders written by presets, analytic-mirror with a good earlier
output set beside it, and hud-direct under a sky. The shared functions are in tests/support/ (statistical
bounds, renders held in memory, hand-built scenes, the command line's contract, the chi-square test, the
add-on's scenario runner), imported as ``from tests.support.<module> import ...`` everywhere."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))  # the tracer, the presets and tests.support, however pytest was started

# The helpers' own assertions report their operands, as the tests' do.
pytest.register_assert_rewrite("tests.support")

from tests.support.cli import hashes, run_cli  # noqa: E402
from tests.support.scenes import edit_json  # noqa: E402


@pytest.fixture
def preset(tmp_path):
    """``preset(name, **kw)``: the preset's scene folder written into tmp_path (keywords as PRESETS[name].write
    takes them: resolution, fov_deg, pupil_mm)."""
    from presets import PRESETS

    def make(name, **kw):
        return PRESETS[name].write(tmp_path / name, **kw)

    return make


@pytest.fixture
def mirror(preset):
    """analytic-mirror at 16 x 12 pixels."""
    return preset("analytic-mirror", resolution=(16, 12))


@pytest.fixture
def earlier(mirror, tmp_path):
    """An output folder holding a good earlier render of ``mirror``: (folder, its hashes)."""
    out = tmp_path / "out"
    code, err = run_cli("render", mirror, "--rays", 100_000, "--workers", 1, "--quiet", "--out", out)
    assert code == 0, err
    return out, hashes(out)


@pytest.fixture(scope="module")
def hud_with_sky(tmp_path_factory):
    """hud-direct at 96 x 48 pixels against a uniform sky of 2000 cd/m^2 (once per test module)."""
    from presets import PRESETS

    folder = PRESETS["hud-direct"].write(tmp_path_factory.mktemp("hud") / "s", resolution=(96, 48))
    edit_json(folder, lambda d: d.update(environment={"type": "uniform", "luminance": 2000.0}))
    return folder


@pytest.fixture(scope="session", autouse=True)
def worker_pool_closed_at_the_end():
    """The session's worker pool (tracer.runtime.parallel.shared_pool), kept from test to test, is closed
    when the tests end, as the command line closes it when its command ends."""
    yield
    from tracer.runtime.parallel import close_shared_pool

    close_shared_pool()
