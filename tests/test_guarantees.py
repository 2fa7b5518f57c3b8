"""The named findings, each pinned: a typed error naming the field, or a correct
number where there was a wrong one (checked against SciPy or a closed form)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import InputError, OutOfRangeError, TolsynthError


@pytest.fixture(scope="module")
def planar():
    return tolsynth.load_model("planar_2r")


@pytest.mark.parametrize("call, field", [
    (lambda m: tolsynth.worst_pose(m, "coarse", step_tol=0), "step_tol"),
    (lambda m: tolsynth.worst_pose(m, "coarse", step_tol=-1e-3), "step_tol"),
    (lambda m: tolsynth.worst_pose(m, "coarse", step_tol=math.nan), "step_tol"),
    (lambda m: tolsynth.worst_pose(tolsynth.load_model("xu_zhang_1988"), "figure3", grid=200), "grid"),
    (lambda m: tolsynth.worst_pose(m, "coarse", grid=10**7), "grid"),
    (lambda m: tolsynth.monte_carlo(m, "worst", "coarse", R=0.5, n=math.nan), "n"),
    (lambda m: tolsynth.monte_carlo(m, "worst", "coarse", R=0.5, n=math.inf), "n"),
    (lambda m: tolsynth.synthesize(m, 0.5, 1 - 1.1e-16), "p"),
    (lambda m: tolsynth.synthesize(m, 0.5, 0.99, x0=[0.0, 0.1, 0.1, 0.1]), "x0[0]"),
    (lambda m: tolsynth.synthesize(m, 0.5, 0.99, options={"tol": -1}), "options['tol']"),
    (lambda m: tolsynth.synthesize(m, 0.5, 0.99, options={"tl": 1e-8}), "options"),
    (lambda m: m.analyze("worst", np.full(4, 1e155), R=0.5), "tolerances[l1]"),
    (lambda m: tolsynth.synthesize_workspace(m, 0.5, 0.99, max_rounds=0), "max_rounds"),
    (lambda m: tolsynth.compare(m, 0.5, 0.99, options="tol"), "options"),
    (lambda m: tolsynth.compare(m, 0.5, 0.99, options={"ipopt": "a"}), "options['ipopt']"),
    (lambda m: tolsynth.compare(m, 0.5, 0.99, options={"ipopt": {"warm_start": 1}}), "options['warm_start']"),
    (lambda m: m.tolerances({"l1": "a", "l2": 1, "o1": 1, "o2": 1}), "tolerances[l1]"),
    (lambda m: m.fk(["a", "b"]), "q"),
    (lambda m: m.index(["l1"]), "error parameter"),
])
def test_typed_error_names_field(planar, call, field):
    with pytest.raises(TolsynthError) as info:
        call(planar)
    assert isinstance(info.value, InputError)
    assert info.value.field == field and field in str(info.value)


def test_ipopt_options_dump_nothing(planar, capfd):
    with pytest.raises(OutOfRangeError):
        tolsynth.synthesize(planar, 0.5, 0.99, options={"tol": -1})
    assert capfd.readouterr().out == ""


def test_p_sphere_at_tiny_radius_is_positive_and_right(planar):
    """At R = 1e-12 mm the closed form cancels (it gave -8e-28); the series gives the value of
    the small-ball limit P ~ R^3 / (3 sqrt(pi/2) prod(sigma)) ... checked here against SciPy's chi
    CDF for equal variances, and positive in general."""
    from scipy.stats import chi

    from tolsynth.probability.stats import p_ball

    for R in (1e-12, 1e-6, 0.3, 0.5, 0.7):
        assert p_ball([2.0, 2.0, 2.0], R) == pytest.approx(chi.cdf(R / math.sqrt(2.0), 3), rel=1e-12, abs=0)
    a = planar.analyze("elbow90", "coarse", R=1e-12)
    assert 0 < a.p_sphere < 1e-20


def test_no_overflow_warning_from_stats():
    """Huge arguments of the chi CDF (variance 1e-300 against R = 1e9) saturate at 1 silently."""
    from tolsynth.probability.stats import p_ball, p_components

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert p_ball([1e-30, 1e-300, 1e-300], 1e9) == 1.0
        assert np.all(p_components([1e-300, 1.0], 1e9) == 1.0)
