"""What a process keeps by key (tracer/core/kept.py): results of any kind, at most a number of them, least
recently used dropped first, each caller given its copy where the kind is one a caller changes."""

import copy

from tracer.core.kept import KeptResults


def test_kept_results_are_made_once_and_the_least_recently_used_go_first():
    made = []

    def make(key):
        return lambda: made.append(key) or {"key": key, "list": [key]}

    kept = KeptResults(2, copy=copy.deepcopy)
    first = kept.get("a", make("a"))
    first["list"].append("changed by a caller")
    assert kept.get("a", make("a")) == {"key": "a", "list": ["a"]}  # kept, and not the caller's copy
    kept.get("b", make("b"))
    kept.get("a", make("a"))  # "a" used last: "b" goes when "c" comes
    kept.get("c", make("c"))
    assert len(kept) == 2 and made == ["a", "b", "c"]
    kept.get("a", make("a"))
    kept.get("b", make("b"))
    assert made == ["a", "b", "c", "b"]
    same = KeptResults(1)  # no copy: the very object (a photon map, which nobody changes)
    obj = object()
    assert same.get(1, lambda: obj) is obj and same.get(1, object) is obj
