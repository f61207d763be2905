"""The code layout: tracer/'s subpackages are layers, and a module imports only from its own layer or
those below it, with no import circle (every import counts, the ones inside functions too)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.paths import ROOT

#: tracer/'s layers, lowest first (docs/dev/architecture.md). ``tracer`` itself (its __init__: the
#: version) lies below them all; the command line above them all.
LAYERS = ("core", "optics", "sources", "scene", "transport", "methods", "runtime", "analysis", "products", "scans",
          "cli")
#: What tracer/ never imports: Blender, and the packages that use the tracer; the command line alone
#: may import the presets (``hud-trace render PRESET``), which are written with the tracer's scene code.
FORBIDDEN = ("bpy", "hud_addon", "presets", "tests", "benchmarks", "tools")
ALLOWED = {"tracer.cli": ("presets",)}


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(root: Path, package: str = "tracer") -> dict[str, set[str]]:
    """{module: the modules of ``package`` it imports, and the outside ones it must not} for every
    module under ``root / package`` (module-level and function-local imports alike); a ``from X import
    y`` counts as an import of X.y where that is a module, else of X."""
    files = {_module_name(p, root): p for p in (root / package).rglob("*.py")}
    out: dict[str, set[str]] = {}
    for name, path in files.items():
        is_pkg = path.name == "__init__.py"
        here = name if is_pkg else name.rpartition(".")[0]
        found = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here.split(".")
                    base = base[:len(base) - (node.level - 1)]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                for a in node.names:
                    sub = f"{target}.{a.name}"
                    found.add(sub if sub in files else target)
        out[name] = found
    return out


def layer(module: str) -> int:
    """The index of ``module``'s layer in :data:`LAYERS`; -1 for the package itself."""
    parts = module.split(".")
    if len(parts) == 1:
        return -1
    return LAYERS.index(parts[1])


def violations(graph: dict[str, set[str]], package: str = "tracer") -> list[str]:
    """Every import against the layer order or of a forbidden package, and every import circle."""
    bad = []
    for module, targets in sorted(graph.items()):
        for t in sorted(targets):
            top = t.split(".")[0]
            if top in FORBIDDEN and top not in ALLOWED.get(module, ()):
                bad.append(f"{module} imports {t}")
            elif top == package and t in graph and layer(t) > layer(module):
                bad.append(f"{module} ({LAYERS[layer(module)] if layer(module) >= 0 else package}) imports {t} "
                           f"({LAYERS[layer(t)]}), a higher layer")
    # Circles: Tarjan's strongly connected components over the package's own modules.
    index, low, stack, on, counter, circles = {}, {}, [], set(), [0], []

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in graph[v]:
                circles.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    bad += [f"import circle: {' -> '.join(c)}" for c in circles]
    return bad


def test_every_module_belongs_to_a_layer():
    graph = imports(ROOT)
    assert {m.split(".")[1] for m in graph if "." in m} == set(LAYERS)


def test_imports_follow_the_layers_without_circles():
    assert violations(imports(ROOT)) == []


def _package(tmp: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        p = tmp / "tracer" / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return tmp


@pytest.mark.parametrize("files,expected", [
    ({"__init__.py": "", "core/__init__.py": "", "core/units.py": "from ..scene import load\n",
      "scene/__init__.py": "", "scene/load.py": "from ..core import units\n"},
     ["tracer.core.units (core) imports tracer.scene.load (scene), a higher layer",
      "import circle: tracer.core.units -> tracer.scene.load"]),
    ({"__init__.py": "", "scene/__init__.py": "", "scene/load.py": "def f():\n    from ..methods import base\n",
      "methods/__init__.py": "", "methods/base.py": ""},
     ["tracer.scene.load (scene) imports tracer.methods.base (methods), a higher layer"]),
    ({"__init__.py": "", "methods/__init__.py": "from . import a\n", "methods/a.py": "from . import b\n",
      "methods/b.py": "from .a import x\n"},
     ["import circle: tracer.methods.a -> tracer.methods.b"]),
    ({"__init__.py": "", "core/__init__.py": "", "core/x.py": "import bpy\n"}, ["tracer.core.x imports bpy"]),
])
def test_the_check_finds_a_wrong_way_import_and_a_circle(tmp_path, files, expected):
    """The check itself: an import of a higher layer (also from inside a function), a circle between two
    modules of a layer and an import of Blender are each reported."""
    assert violations(imports(_package(tmp_path, files))) == expected


def test_loading_a_scene_imports_no_method():
    """The scene format validates every method's options without importing a method."""
    code = ("import sys, tracer.scene; "
            "print(sorted(m for m in sys.modules if m.startswith(('tracer.methods', 'tracer.transport'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "[]"


def test_every_method_has_its_options_in_the_scene_format():
    from tracer.methods import INTEGRATORS
    from tracer.scene.methods import METHOD_OPTIONS

    assert list(METHOD_OPTIONS) and set(METHOD_OPTIONS) == set(INTEGRATORS)
