"""Fuzzing ``hud-trace render``: seeded mutations of the presets' scene.json, their meshes and
the command-line arguments, each rendered in this process into a folder holding an earlier output set.

The contract (docs/user/cli.md, the exit statuses of render), asserted for every case:
- no exception escapes (a traceback for the user), no hang (an alarm), no RuntimeWarning (a NaN or
  an overflow somewhere);
- exit 0 or 3: image.exr, preview.png and report.json of one run (the EXR's run id is the report's),
  every pixel finite and non-negative, the report strict JSON (no NaN or Infinity);
- exit 2: one line, "error: ", naming scene.json, the mesh or texture, or the argument; the earlier
  outputs byte for byte as they were;
- never any other status, never a staging file left in the folder.

Case k of the suite is random.Random(SEED + k): a failure names its case, and the case alone replays
it (``pytest tests/cli/test_fuzz.py -k "case_17"``)."""

from __future__ import annotations

import copy
import hashlib
import io
import json
import random
import shutil
import signal
import warnings
from contextlib import redirect_stderr
from pathlib import Path

import numpy as np
import pytest

from tracer import cli
from tracer.core.imageio import read_exr_channels

SEED = 20261130
CASES = 300
#: Presets fuzzed, and the small resolution every case starts from (so that valid renders are quick).
PRESETS = ("hud-direct", "analytic-mirror", "analytic-disk", "analytic-furnace")
RESOLUTION = [8, 6]
OUTPUTS = ("image.exr", "preview.png", "report.json")
#: Seconds a case may take before it counts as a hang.
HANG_S = 60

#: Values that replace a field: wrong types, out of every range, non-finite, paths out of the folder.
NASTY = [0, -1, 1, 0.5, -0.0, 1e-308, 5e-324, 1e308, -1e308, 1e39, 10**400, -(10**400), 2**63, float("nan"),
         float("inf"), float("-inf"), "", "x", "1", "../../etc/passwd", "/etc/passwd", "meshes/../../x.obj",
         "\u00e9\u0000", None, True, False, [], {}, [1, 2], [1, 2, 3], [1, 2, 3, 4], [[1, 2], [3, 4]],
         [1e308, 0, 0], [float("nan"), 0, 0], [0, 0, 0], [-1, -1, -1], {"type": "uniform"}, [[]] * 4,
         [[0.0] * 4] * 4, [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]], "uniform", "hdri", "none", "mirror",
         "dielectric", "lcd", "eye", "object", 16384, 16385, 4096, 65, 3.5]


def _paths(node, prefix=()):
    """Every key path into a JSON tree (containers and leaves)."""
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


def _get(node, path):
    for k in path:
        node = node[k]
    return node


def _numbers(node, prefix=()):
    """Key paths of the numeric leaves of a JSON tree."""
    return [p for p in _paths(node, prefix) if p and isinstance(_get(node, p), (int, float))
            and not isinstance(_get(node, p), bool)]


def vary_json(data: dict, rng: random.Random) -> dict:
    """One to three plausible changes, as a user would make (most still valid): a number scaled or
    shifted, a material copied to another object, an object removed, an emitter added, the
    environment or the method options changed."""
    data = copy.deepcopy(data)
    for _ in range(rng.choice((1, 2, 3))):
        op = rng.randrange(7)
        objs = data["objects"]
        if op == 0:
            path = rng.choice(_numbers(data))
            parent = _get(data, path[:-1])
            parent[path[-1]] = parent[path[-1]] * rng.uniform(0.5, 2.0) + rng.choice((0, 0, rng.gauss(0, 5)))
        elif op == 1 and len(objs) > 1:
            a, b = rng.sample(range(len(objs)), 2)
            objs[b]["material"] = copy.deepcopy(objs[a]["material"])
        elif op == 2 and objs:
            del objs[rng.randrange(len(objs))]
        elif op == 3 and objs:
            rng.choice(objs)["emission"] = {"luminance": 10 ** rng.uniform(-3, 6),
                                            "two_sided": rng.random() < 0.5}
        elif op == 4:
            data["environment"] = rng.choice(({"type": "none"},
                                              {"type": "uniform", "luminance": 10 ** rng.uniform(-2, 4)}))
        else:
            method = rng.choice(("forward", "backward"))
            opts = data.setdefault("methods", {}).setdefault(method, {})
            opts["max_depth"] = rng.randint(1, 40)
            if method == "backward":
                opts["next_event"] = rng.random() < 0.7
    return data


def mutate_json(data: dict, rng: random.Random) -> dict:
    """One to three structural mutations of a scene description."""
    data = copy.deepcopy(data)
    for _ in range(rng.choice((1, 1, 2, 3))):
        paths = [p for p in _paths(data) if p]
        path = rng.choice(paths)
        parent = _get(data, path[:-1])
        op = rng.random()
        value = _get(data, path)
        if op < 0.45:
            parent[path[-1]] = rng.choice(NASTY)
        elif op < 0.6 and isinstance(value, (int, float)) and not isinstance(value, bool):
            parent[path[-1]] = value * rng.choice((-1, 0, 1e-30, 1e-6, 1e3, 1e30, 1e300))
        elif op < 0.75:
            if isinstance(parent, dict):
                del parent[path[-1]]
            else:
                del parent[path[-1]]
        elif op < 0.85 and isinstance(parent, dict):
            parent[rng.choice(("extra", "Luminance", "type ", "comment"))] = rng.choice(NASTY)
        elif op < 0.93 and isinstance(value, list) and value:
            parent[path[-1]] = value + value[:1] if rng.random() < 0.5 else value[:-1]
        else:
            other = _get(data, rng.choice(paths))
            parent[path[-1]] = copy.deepcopy(other)
    return data


def mutate_text(text: str, rng: random.Random) -> str:
    """A textual mutation: truncation, a duplicated key, a stray byte, deep nesting."""
    op = rng.randrange(5)
    if op == 0:
        return text[:rng.randrange(len(text))]
    if op == 1:
        i = text.index("{", 1)
        return text[:i + 1] + ' "name": "twice",' + text[i + 1:] if '"name"' in text[i:] else text + "x"
    if op == 2:
        i = rng.randrange(len(text))
        return text[:i] + rng.choice(("\x00", "}", "]", ",", "\ufeff", "NaN", "Infinity", "\\")) + text[i:]
    if op == 3:
        return "[" * 50_000 + text + "]" * 50_000
    return text.replace(":", ": -", 1)


def mutate_texture(folder: Path, rng: random.Random) -> str:
    """Spoil one texture: truncated (libpng then prints its own error lines), garbage, empty,
    deleted. Returns a description."""
    tex = rng.choice(sorted((folder / "textures").iterdir()))
    data = tex.read_bytes()
    op = rng.randrange(4)
    if op == 0:
        tex.write_bytes(data[:rng.randrange(1, len(data))])
    elif op == 1:
        tex.write_bytes(bytes(rng.randrange(256) for _ in range(200)))
    elif op == 2:
        tex.write_bytes(b"")
    else:
        tex.unlink()
    return f"texture {tex.name} op {op}"


def mutate_mesh(folder: Path, rng: random.Random) -> str:
    """Spoil one mesh file of the scene: truncated, a non-finite or huge vertex, no faces, deleted,
    a face index out of range. Returns a description."""
    if (folder / "textures").is_dir() and rng.random() < 0.3:
        return mutate_texture(folder, rng)
    meshes = sorted((folder / "meshes").iterdir())
    mesh = rng.choice(meshes)
    lines = mesh.read_text().splitlines()
    op = rng.randrange(6)
    if op == 0:
        mesh.write_text("\n".join(lines[:rng.randrange(len(lines))]) + "\n")
    elif op == 1:
        v = [i for i, ln in enumerate(lines) if ln.startswith("v ")]
        lines[rng.choice(v)] = f"v {rng.choice(('nan', 'inf', '1e39', '-1e308', '1e30'))} 0 0"
        mesh.write_text("\n".join(lines) + "\n")
    elif op == 2:
        mesh.write_text("\n".join(ln for ln in lines if not ln.startswith("f ")) + "\n")
    elif op == 3:
        mesh.unlink()
    elif op == 4:
        mesh.write_text("\n".join(lines) + "\nf 1 2 999999\n")
    else:
        mesh.write_bytes(b"\xff\xfe" + mesh.read_bytes()[:100])
    return f"mesh {mesh.name} op {op}"


#: Valid and invalid values of each render argument.
ARGS = {"--method": (["backward", "forward"], ["nope", ""]),
        "--rays": (["1", "100", "5000", "20000", "40000"], ["0", "-5", "1e3", "x", str(10**16)]),
        "--seconds": (["0.3", "1e-9", "0.05"], ["nan", "inf", "-1", "0", "1e300"]),
        "--seed": (["0", "1", str(2**63 - 1)], [str(2**63), "-1", "0.5"]),
        "--batch-size": (["1024", "4096", "100000"], ["1", "0", "-1", str(10**12)]),
        "--workers": (["1"], ["0", "-3", "2000"])}


def cli_args(rng: random.Random, bad: bool) -> list[str]:
    """A method, a budget (rays or seconds), maybe a seed and a batch size, one worker: all valid
    and small, or (``bad``) with one argument out of its range or malformed."""
    flags = ["--method", rng.choice(("--rays", "--rays", "--rays", "--seconds")), "--workers"]
    flags += [f for f in ("--seed", "--batch-size") if rng.random() < 0.3]
    wrong = rng.choice(flags) if bad else None
    args = []
    for f in flags:
        good, nasty = ARGS[f]
        args += [f, rng.choice(nasty if f == wrong else good)]
    return args


@pytest.fixture(scope="module")
def bases(tmp_path_factory):
    """Per preset: (scene folder at RESOLUTION, its scene.json, an output folder with an earlier render)."""
    from presets import PRESETS as ALL

    root = tmp_path_factory.mktemp("fuzz")
    out = {}
    for name in PRESETS:
        folder = ALL[name].write(root / name)
        data = json.loads((folder / "scene.json").read_text())
        data["eye"]["resolution"] = RESOLUTION
        (folder / "scene.json").write_text(json.dumps(data))
        earlier = root / f"{name}-out"
        code, err = run(["render", str(folder), "--rays", "20000", "--workers", "1", "--quiet", "--out", str(earlier)])
        assert code == 0, err
        out[name] = (folder, data, earlier)
    return out


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang(f"no answer within {HANG_S} s")


def run(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(HANG_S)
    try:
        with redirect_stderr(err), warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            try:
                code = cli.main(argv)
            except SystemExit as e:  # argparse: a malformed argument
                code = e.code
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    return code, err.getvalue()


def _hashes(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def _strict_json(text: str):
    def bad(token):
        raise ValueError(f"{token} in report.json")

    return json.loads(text, parse_constant=bad)


def make_case(k: int, bases, tmp: Path) -> tuple[str, list[str], str]:
    """Case k: (description, argv, the folder rendered into)."""
    rng = random.Random(SEED + k)
    name = rng.choice(PRESETS)
    base, data, earlier = bases[name]
    folder = tmp / "scene"
    shutil.copytree(base, folder)
    out = tmp / "out"
    shutil.copytree(earlier, out)
    what = rng.random()
    if what < 0.35:
        (folder / "scene.json").write_text(json.dumps(vary_json(data, rng)))
        desc = "variation"
    elif what < 0.6:
        (folder / "scene.json").write_text(json.dumps(mutate_json(data, rng)))
        desc = "json"
    elif what < 0.72:
        (folder / "scene.json").write_text(mutate_text(json.dumps(data, indent=1), rng))
        desc = "text"
    elif what < 0.82:
        desc = mutate_mesh(folder, rng)
    else:
        desc = "arguments"
    argv = ["render", str(folder), *cli_args(rng, bad=desc == "arguments" and rng.random() < 0.5), "--quiet",
            "--out", str(out)]
    return f"{name} {desc}", argv, str(out)


@pytest.mark.parametrize("k", range(CASES), ids=[f"case_{k}" for k in range(CASES)])
def test_fuzz_case(k, bases, tmp_path):
    desc, argv, out = make_case(k, bases, tmp_path)
    out = Path(out)
    before = _hashes(out)
    code, err = run(argv)
    context = f"case {k} ({desc}): {' '.join(argv[2:-3])}\n{err}"
    assert code in (0, 2, 3), context
    assert not any(p.name.startswith(".hud-") for p in out.iterdir()), context
    if code == 2:
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), context
        assert any(w in lines[0] for w in ("scene.json", "meshes/", "textures/", "--")), context
        assert _hashes(out) == before, context
        return
    assert sorted(p.name for p in out.iterdir()) == sorted(OUTPUTS), context
    report = _strict_json((out / "report.json").read_text())
    ch, attrs = read_exr_channels(out / "image.exr")
    assert attrs["hud:run_id"] == report["run_id"], context
    for name, c in ch.items():
        assert np.all(np.isfinite(c)) and c.min() >= 0, (name, context)
    assert (code == 3) == (report["paths_found_light"] == 0), context
