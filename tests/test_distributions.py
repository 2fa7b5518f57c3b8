"""A distribution per error parameter: mixed shapes in one mechanism, through
the API, the command line and model files, checked by Monte Carlo through the nonlinear chain and
by the covariance written out by hand."""

import json
import subprocess
import sys

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import InputError, ModelFileError, OutOfRangeError
from tolsynth.probability.distributions import shape

MIXED = {"*": "uniform", "h2": "normal", "h3": "triangular", "a": "truncnormal", "alpha1": "truncnormal(3)"}


def test_mixed_covariance_is_the_sum_of_each_parameters_own_variance(xz):
    """analyze's covariance = S diag(eps_i^2 Var(Y_i)) S^T with each shape's variance by hand."""
    eps = xz.tolerances("figure3")
    a = xz.analyze("worst", eps, MIXED, R=0.3)
    S = xz.sensitivity(xz.joints("worst"))[:3]
    var = {"uniform": 1 / 3, "normal": 1 / 9, "triangular": 1 / 6}
    v = []
    for nm in xz.error_parameters:
        s = MIXED.get(nm, "uniform")
        v.append(var[s] if s in var else shape(s).variance)
    np.testing.assert_allclose(a.covariance, (S * (eps**2 * np.array(v))) @ S.T, rtol=1e-12)
    # truncnormal(2): Var = (1 - 4 phi(2) / (2 Phi(2) - 1)) / 4 = (1 - 4 * 0.05399097 / 0.95449974) / 4
    assert shape("truncnormal").variance == pytest.approx((1 - 4 * 0.05399097 / 0.95449974) / 4, rel=1e-6)


def test_mixed_optimum_is_checked_by_monte_carlo(xz):
    """The optimum with mixed shapes meets z sigma_1 = R, and a 200k-sample nonlinear Monte Carlo
    drawing each error from its own shape gives the analytic principal spreads within 1 %."""
    r = tolsynth.synthesize(xz, R=0.5, p=0.99, distribution=MIXED, probability="gaussian")
    assert r.success
    a = xz.analyze("worst", r.x, MIXED, R=0.5)
    assert a.principal_std[0] * 2.5758293 == pytest.approx(0.5, rel=1e-6)
    mc = tolsynth.monte_carlo(xz, "worst", r.x, MIXED, R=0.5, n=200_000, seed=3)
    np.testing.assert_allclose(mc.principal_std, a.principal_std, rtol=0.01)
    # and it differs from both all-uniform and all-normal designs
    cu = tolsynth.synthesize(xz, R=0.5, p=0.99, distribution="uniform", probability="gaussian").cost
    cn = tolsynth.synthesize(xz, R=0.5, p=0.99, distribution="normal", probability="gaussian").cost
    assert cn < r.cost < cu


def test_model_file_declares_shapes_and_the_default_uses_them(tmp_path):
    from tolsynth.model.reader import model_path

    text = model_path("xu_zhang_1988").read_text()
    text = text.replace('name = "h3"\n', 'name = "h3"\ndistribution = "normal"\n', 1)
    f = tmp_path / "xu_mixed.toml"
    f.write_text(text)
    m = tolsynth.load_model(str(f))
    assert m.distribution["h3"] == "normal" and m.distribution["h2"] == "uniform"
    r_file = tolsynth.synthesize(m, R=0.5, p=0.99, probability="gaussian")  # distribution=None: the file's shapes
    r_api = tolsynth.synthesize(
        tolsynth.load_model("xu_zhang_1988"), R=0.5, p=0.99, distribution={"h3": "normal"}, probability="gaussian"
    )
    assert r_file.cost == pytest.approx(r_api.cost, rel=1e-7)  # the solver tolerance
    # distribution= as a string still sets every parameter at once
    r_all = tolsynth.synthesize(m, R=0.5, p=0.99, distribution="uniform", probability="gaussian")
    assert r_all.cost == pytest.approx(
        tolsynth.synthesize("xu_zhang_1988", R=0.5, p=0.99, probability="gaussian").cost, rel=1e-9
    )
    bad = text.replace('distribution = "normal"', 'distribution = "cauchy"')
    f.write_text(bad)
    with pytest.raises(ModelFileError, match=r"error_parameters\[1\]\.distribution"):
        tolsynth.load_model(str(f))


def test_bad_per_parameter_input_is_typed(xz):
    with pytest.raises(Exception, match="nope"):
        tolsynth.synthesize(xz, R=0.5, p=0.99, distribution={"nope": "normal"}, probability="gaussian")
    with pytest.raises(OutOfRangeError, match=r"distribution\[h2\]"):
        tolsynth.synthesize(xz, R=0.5, p=0.99, distribution={"h2": "gamma"}, probability="gaussian")
    with pytest.raises(InputError, match="distribution"):
        tolsynth.synthesize(xz, R=0.5, p=0.99, distribution={}, probability="gaussian")


def test_command_line_takes_per_parameter_shapes():
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "tolsynth",
            "analyze",
            "--model",
            "xu_zhang_1988",
            "--tolerances",
            "figure3",
            "--R",
            "0.3",
            "--dist",
            "*=uniform,h2=normal",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    xz = tolsynth.load_model("xu_zhang_1988")
    a = xz.analyze("worst", "figure3", {"*": "uniform", "h2": "normal"}, R=0.3)
    np.testing.assert_allclose(d["principal_std"], a.principal_std, rtol=1e-12)
    bad = subprocess.run(
        [
            sys.executable,
            "-m",
            "tolsynth",
            "analyze",
            "--model",
            "xu_zhang_1988",
            "--tolerances",
            "figure3",
            "--dist",
            "h2=gamma",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert bad.returncode != 0 and "Traceback" not in bad.stderr and "--dist" in bad.stderr


def test_shapes_of_names_the_entry_field_and_the_allowed_values():
    """Without a mechanism an unknown name is the same UnknownNameError a mechanism gives (the
    entry as the field, the names allowed); a bad shape, the "*" default included, names its entry
    and lists every shape."""
    from tolsynth.errors import UnknownNameError
    from tolsynth.probability.distributions import shapes_of

    names = ("l1", "l2", "o1", "o2")
    with pytest.raises(UnknownNameError) as info:
        shapes_of({"bad": "uniform"}, names)
    assert info.value.field == "distribution[bad]" and "'bad'" in str(info.value)
    assert info.value.allowed == "one of l1, l2, o1, o2"
    for dist, field in (
        ({"*": "bogus"}, "distribution[*]"),
        ({"l1": "truncnormal(20)"}, "distribution[l1]"),
        (["uniform", "uniform", "uniform", 3], "distribution[o2]"),
    ):
        with pytest.raises(OutOfRangeError) as info:
            shapes_of(dist, names)
        assert info.value.field == field
        assert all(s in info.value.allowed for s in ("'uniform'", "'normal'", "'triangular'", "0.5 <= beta <= 8"))
    m = tolsynth.load_model("planar_2r")
    with pytest.raises(UnknownNameError) as info:
        tolsynth.synthesize(m, R=0.5, p=0.99, pose="elbow90", distribution={"bad": "uniform"})
    assert info.value.field == "distribution[bad]"
