"""The main line of a workspace exchange's output states what is proven: the cost with the
exchange's lower bound over every pose and its gap, the last solve's dual bound labelled as its own.
The bound is checked against an independent solve at the exchange's final poses (at R itself, in
the reading proven), whose certified optimum bounds the cost of any design meeting R everywhere."""

import contextlib
import io
import json
import re

import numpy as np
import pytest

import tolsynth
from tolsynth.cli import main

BASE = ["solve", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--everywhere", "--certify"]


def _cli(argv):
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(argv) == 0
    return buf.getvalue()


@pytest.mark.parametrize(
    "extra, probability",
    [(["--through-sigma"], "exact"), (["--margin", "3e-3", "--probability", "gaussian"], "gaussian")],
)
def test_main_line_gives_the_exchanges_bound(extra, probability):
    out = json.loads(_cli([*BASE, *extra, "--json"]))
    text = _cli([*BASE, *extra])
    m = tolsynth.load_model("planar_2r")
    at_poses = tolsynth.synthesize(m, R=0.5, p=0.99, probability=probability, poses=[np.array(q) for q in out["poses"]])
    assert at_poses.success
    bound = at_poses.cost  # the cheapest design meeting R at the final poses
    line = next(ln for ln in text.splitlines() if ln.startswith("cost "))
    got = re.match(
        r"cost (\S+)  \(lower bound (\S+) over every pose, gap (\S+); the last solve's dual bound at its 2 pose\(s\) (\S+)\)",
        line,
    )
    assert got, line
    cost, lower, gap, last = map(float, got.groups())
    assert lower == pytest.approx(bound, rel=1e-6) and out["lower_bound"] == pytest.approx(bound, rel=1e-6)
    assert gap == pytest.approx(cost - bound, rel=1e-2) and gap > 1e-3 * cost
    assert last == pytest.approx(cost, rel=1e-6)  # the last solve's own, at its poses (or at R')
    ws = tolsynth.synthesize_workspace(
        m,
        0.5,
        0.99,
        probability=probability,
        certify=True,
        certify_options={"through": "sigma"} if probability == "exact" else {"margin": 3e-3},
    )
    assert line in ws.summary().splitlines()
