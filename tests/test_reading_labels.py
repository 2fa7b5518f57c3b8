"""Every probability shown names its reading (docs/probability.md): the worst-pose search's and
the map's sphere probability (Gaussian), and a report of an exact design (its Specification in the
exact reading, its Contributions section's sphere probability exact, the Gaussian one labelled).
The values are checked against independent computations: SciPy's double integral of the normal
density over the ball with the principal sigmas, and the reference evaluator of the exact sphere probability."""

import contextlib
import io
import json
import re

import numpy as np
import pytest

import tolsynth
from test_stats import ball_probability_scipy
from tolsynth.cli import main
from tolsynth.probability.exact_sphere import ball_probability


def _cli(argv):
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(argv) == 0
    return buf.getvalue()


@pytest.mark.slow  # 8 s: two worst-pose searches
def test_worst_pose_sphere_probability_is_labelled_gaussian():
    argv = ["worst-pose", "--model", "xu_zhang_1988", "--criterion", "probability", "--R", "0.2"]
    text = _cli(argv)
    out = json.loads(_cli([*argv, "--json"]))
    assert "criterion probability (Gaussian P(|dr|<=0.2 mm))" in text
    assert re.search(r"P\(\|dr\|<=R\), Gaussian\s+0\.214819", text)
    assert out["probability"] == "gaussian"
    # the value is the Gaussian sphere probability of its principal sigmas (0.2148), not the exact (0.1999)
    gauss = ball_probability_scipy(np.square(out["principal_std"]), 0.2)
    assert out["value"] == pytest.approx(gauss, abs=1e-7)
    m = tolsynth.load_model("xu_zhang_1988")
    exact = ball_probability(
        m.sensitivity(np.array(out["q"]))[:3], np.array(list(out["tolerances"].values())), ["uniform"] * m.n, 0.2
    )
    assert abs(out["value"] - exact) > 0.01


def test_map_says_gaussian_and_records_it(tmp_path):
    data = tmp_path / "map.csv"
    text = _cli(["map", "--model", "xu_zhang_1988", "--R", "0.5", "--n", "6", "--data", str(data)])
    assert "P(|dr|<=R)   " in text and "(Gaussian: normal errors of the uniform errors' variances" in text
    assert "P(dr<=R)" not in text
    assert json.loads(data.with_name("map.csv.json").read_text())["tolsynth"]["inputs"]["probability"] == "gaussian"


@pytest.mark.slow  # 6 s: an exact design and its Monte Carlo
def test_report_of_an_exact_design_reads_its_probabilities_exactly(tmp_path):
    m = tolsynth.load_model("xu_zhang_1988")
    path = tmp_path / "r.md"
    tolsynth.report(m, R=0.5, p=0.99, path=str(path), mc_samples=500, map_n=0, worst_grid=0)
    md = path.read_text()
    spec = md[md.index("1. Specification") : md.index("2. Model")]
    assert "per principal component" not in spec
    assert "P(\\|u . dr\\| &lt;= R) &gt;= p in the linear error model's exact distribution" in spec
    assert "(the Gaussian reading's, not used by this exact design)" in spec
    res = tolsynth.synthesize(m, R=0.5, p=0.99)
    A = m.sensitivity(m.joints("worst"))[:3]
    exact = ball_probability(A, res.x, ["uniform"] * m.n, 0.5)
    sigma = np.sqrt(np.linalg.eigvalsh((A * res.x**2 / 3) @ A.T))  # uniform +-eps: variance eps^2 / 3
    head = re.search(
        r"P\(\\\|dr\\\| &lt;= 0\.5 mm\) = (\S+) exact \(Gaussian (\S+), the one the last column splits\)", md
    )
    assert head, md[md.index("5. Contributions") :][:600]
    assert float(head.group(1)) == pytest.approx(exact, abs=1e-6)
    assert float(head.group(2)) == pytest.approx(ball_probability_scipy(sigma**2, 0.5), abs=2e-6)
