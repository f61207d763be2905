"""What the add-on scenarios share inside Blender: imported only by scenario functions, which
tests/addon/blender_runner.py runs in a process that has imported bpy (importing this module imports bpy)."""

from __future__ import annotations

import bpy

from hud_addon.batch import enable_from_source  # noqa: F401  (for the scenarios: the add-on from this checkout)


def disable(module: str):
    """Disable the add-on ``module`` (every scenario does so before it returns: the process would hang at
    exit while its render engine is registered)."""
    import addon_utils  # importable once bpy is

    addon_utils.disable(module)


def hud_names() -> list[str]:
    """The add-on's classes registered in bpy.types."""
    return sorted(n for n in dir(bpy.types) if n.startswith(("HUD_", "HudRender", "HudScene", "HudObject")))


class _Pass:
    """Stands in for a render pass: keeps a sample of the values set."""

    def __init__(self, channels, n):
        self.channels, self.n, self.values = channels, n, None
        self.rect = self

    def foreach_set(self, values):
        assert len(values) == self.n * self.channels, (len(values), self.n, self.channels)
        self.values = list(map(float, values[:: max(1, len(values) // 1000)]))


class StubEngine:
    """Stands in for a RenderEngine: test_break turns true after ``stop_after`` calls, or (``stop_after``
    None) at the first call after the render reported progress, that is after its first merged batch."""

    def __init__(self, stop_after):
        self.stop_after, self.calls, self.progress, self.reports, self.passes = stop_after, 0, [], [], {}
        self.updates, self.stamps, self.result = 0, {}, None

    def test_break(self):
        self.calls += 1
        return bool(self.progress) if self.stop_after is None else self.calls > self.stop_after

    def update_progress(self, f):
        self.progress.append(f)

    def update_stats(self, a, b):
        pass

    def report(self, kind, msg):
        self.reports.append(msg)

    def add_pass(self, name, channels, chan_id):
        self.passes[name] = channels

    def begin_result(self, x, y, w, h):
        class Layer:
            passes = {"Combined": _Pass(4, w * h), **{k: _Pass(c, w * h) for k, c in self.passes.items()}}

        stamps = self.stamps

        class Result:
            layers = [Layer()]

            @staticmethod
            def stamp_data_add_field(key, value):
                stamps[key] = value

        self.result = Result()
        return self.result

    def update_result(self, rr):
        self.updates += 1

    def get_result(self):
        return self.result

    def end_result(self, rr):
        pass


class Layout:
    """Stands in for a panel's layout: counts the labels drawn."""

    def __init__(self, counter):
        self.counter = counter

    def label(self, text="", icon="NONE"):
        self.counter.append(text)

    def __getattr__(self, name):
        if name in ("column", "row", "box", "grid_flow"):
            return lambda *a, **k: Layout(self.counter)
        return lambda *a, **k: None
