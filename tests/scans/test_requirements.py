"""A sweep's requirements (``--require``, tracer.scans.requirements): their syntax, and how a report is
judged against one."""

import pytest

from tracer import cli
from tracer.scans.fields import MAX_RUNS, SweepArgumentError
from tracer.scans.requirements import parse_requirement


def test_requirement_syntax():
    q = parse_requirement("hud.spot.peak_over_median_background<=1.2")
    assert (q.key, q.op, q.value) == ("hud.spot.peak_over_median_background", "<=", 1.2)
    report = {"hud": {"spot": {"peak_over_median_background": 1.3}}}
    assert q.judge(report) == {"requirement": q.text, "value": 1.3, "met": False,
                               "why": "hud.spot.peak_over_median_background is 1.3"}
    assert q.judge({"hud": None})["why"] == "hud is not a block"
    assert parse_requirement("rays > 1").judge({"rays": 1})["met"] is False
    assert parse_requirement("rays >= 1").judge({"rays": 1})["met"] is True
    with pytest.raises(SweepArgumentError):
        parse_requirement("x => 1")
    assert str(MAX_RUNS) in cli.build_parser()._subparsers._group_actions[0].choices["sweep"].format_help()
