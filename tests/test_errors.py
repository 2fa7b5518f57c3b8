"""Bad input gets a typed error that names the field (and the allowed range); nothing is clipped.

Each case asserts the exception class (from ``tolsynth.errors``) and that the offending field's
name appears in the message.  Malformed model files are written to ``tmp_path`` from the bundled
files with one defect each.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import tolsynth
from test_kinematics import planar_fk, xu_fk
from tolsynth.errors import (
    InputError,
    LoopClosureError,
    ModelFileError,
    OutOfRangeError,
    TolsynthError,
    UnknownNameError,
)
from tolsynth.probability.stats import p_ball, p_components, p_cone, z_of_p

MODELS_DIR = Path(__file__).resolve().parent.parent / "models"


def _raises(cls, *fragments):
    """pytest.raises(cls) whose message must contain every fragment (plain text)."""
    return pytest.raises(cls, match="(?s)" + "".join(f"(?=.*{re.escape(f)})" for f in fragments))


# ---------------------------------------------------------------------------------------------
# names
# ---------------------------------------------------------------------------------------------
def test_unknown_model_name():
    with _raises(UnknownNameError, "model", "no_such_robot", "xu_zhang_1988", "puma560") as info:
        tolsynth.load_model("no_such_robot")
    assert info.value.field == "model"
    assert isinstance(info.value, TolsynthError) and isinstance(info.value, ValueError)


def test_missing_model_file(tmp_path):
    with _raises(UnknownNameError, "model", "absent.toml"):
        tolsynth.load_model(tmp_path / "absent.toml")


def test_unknown_parameter_in_deltas(xz):
    with _raises(UnknownNameError, "deltas[h9]", "'h9'", "h2", "alpha4"):
        xz.fk("worst", deltas={"h9": 0.1})
    with _raises(UnknownNameError, "deltas[x12]", "'x12'"):
        xz.sensitivity("worst", deltas={"x12": 0.1})


def test_unknown_parameter_or_set_in_tolerances(xz):
    eps = dict(zip(xz.error_parameters, xz.tolerances("figure3")))
    with _raises(UnknownNameError, "tolerances[h7]", "'h7'"):
        xz.tolerances({**eps, "h7": 0.1})
    with _raises(UnknownNameError, "tolerances", "'figure4'", "figure3"):
        xz.tolerances("figure4")
    with _raises(UnknownNameError, "tolerances", "'figure4'"):
        xz.analyze("worst", "figure4", R=0.2)
    del eps["a"]
    with _raises(InputError, "tolerances", "'a'"):
        xz.tolerances(eps)


def test_unknown_configuration(xz):
    with _raises(UnknownNameError, "configuration", "'best'", "worst"):
        xz.fk("best")


def test_wrong_number_of_values(xz):
    with _raises(InputError, "q", "5 values"):
        xz.fk(np.zeros(4))
    with _raises(InputError, "deltas", "11"):
        xz.fk("worst", deltas=np.zeros(3))
    with _raises(InputError, "tolerances", "11"):
        xz.tolerances(np.ones(10))


# ---------------------------------------------------------------------------------------------
# numbers out of range
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("R", [0.0, -0.2, math.nan, math.inf])
def test_R_must_be_positive(xz, R):
    with _raises(OutOfRangeError, "R", "> 0"):
        p_ball([1.0, 1.0, 1.0], R)
    with _raises(OutOfRangeError, "R", "> 0"):
        p_components([0.1, 0.1, 0.1], R)
    with _raises(OutOfRangeError, "R", "> 0"):
        xz.analyze("worst", "figure3", R=R)


@pytest.mark.parametrize("Phi", [0.0, -1e-3])
def test_Phi_must_be_positive(xz, Phi):
    with _raises(OutOfRangeError, "Phi", "> 0"):
        p_cone(np.eye(3) * 1e-8, [0, 0, 1], Phi)
    with _raises(OutOfRangeError, "Phi", "> 0"):
        xz.analyze("worst", "figure3", Phi=Phi)


@pytest.mark.parametrize("p", [0.0, 1.0, -0.1, 1.5, math.nan])
def test_probability_outside_open_unit_interval(p):
    with _raises(OutOfRangeError, "p", "0 < p < 1"):
        z_of_p(p)


def test_negative_or_nonfinite_tolerance(xz):
    eps = dict(zip(xz.error_parameters, xz.tolerances("figure3")))
    for bad in (-0.01, math.nan, math.inf):
        with _raises(OutOfRangeError, "tolerances[hp3]", ">= 0"):
            xz.tolerances({**eps, "hp3": bad})
    vec = xz.tolerances("figure3")
    vec[9] = -1e-3
    with _raises(OutOfRangeError, "tolerances[alpha3]", ">= 0"):
        xz.analyze("worst", vec, R=0.2)


def test_negative_variance(xz):
    with _raises(OutOfRangeError, "variances", ">= 0"):
        p_ball([1.0, -0.5, 0.1], 1.0)


def test_unknown_distribution(xz):
    with _raises(OutOfRangeError, "distribution", "uniform", "normal"):
        xz.analyze("worst", "figure3", distribution="lognormal", R=0.2)


# ---------------------------------------------------------------------------------------------
# joints: limits and the interference constraint, nothing clipped
# ---------------------------------------------------------------------------------------------
def _q_deg(theta1=0.0, thetap2=170.0, theta2=90.0, theta4=0.0, theta5=0.0):
    return np.radians([theta1, thetap2, theta2, theta4, theta5])


def test_joint_outside_its_limits(xz):
    with _raises(OutOfRangeError, "q[thetap2]", "140 to 200 deg", "210.0000"):
        xz.fk(_q_deg(thetap2=210.0))
    with _raises(OutOfRangeError, "q[theta1]", "-150 to 150 deg"):
        xz.sensitivity(_q_deg(theta1=-151.0))
    with _raises(OutOfRangeError, "q[theta4]", "-110 to 110 deg"):
        xz.analyze(_q_deg(theta4=111.0), "figure3", R=0.2)
    with _raises(OutOfRangeError, "q[q2]", "-150 to 150 deg"):
        tolsynth.load_model("planar_2r").fk(np.radians([0.0, 151.0]))


def test_interference_limit(xz):
    """Both joints inside their own ranges, their difference 45 deg < 50 deg (and 135 > 130)."""
    with _raises(OutOfRangeError, "interference", "thetap2", "theta2", "50 to 130 deg"):
        xz.fk(_q_deg(thetap2=145.0, theta2=100.0))
    with _raises(OutOfRangeError, "interference", "50 to 130 deg"):
        xz.fk(_q_deg(thetap2=190.0, theta2=55.0))
    # the worst pose waives it by name (declared in the file), any other vector does not
    q = xz.configurations["worst"].copy()
    q[1] += 1e-6
    with _raises(OutOfRangeError, "interference"):
        xz.fk(q)


def test_nothing_is_clipped(xz):
    """At the limits the pose is that of the given joints; past them, with the check switched
    off, still the pose of the given joints (compared with the NumPy chain)."""
    at_limit = _q_deg(thetap2=200.0, theta2=130.0, theta4=-110.0)  # gamma = 70
    assert np.max(np.abs(xz.fk(at_limit) - xu_fk(at_limit))) < 1e-9
    at_interference = _q_deg(thetap2=180.0, theta2=130.0)  # gamma = 50 exactly
    assert np.max(np.abs(xz.fk(at_interference) - xu_fk(at_interference))) < 1e-9
    past = _q_deg(thetap2=205.0, theta2=130.0, theta4=115.0)
    assert np.max(np.abs(xz.fk(past, check_limits=False) - xu_fk(past))) < 1e-9
    m = tolsynth.load_model("planar_2r")
    q = np.radians([175.0, -160.0])
    assert np.max(np.abs(m.fk(q, check_limits=False) - planar_fk(q))) < 1e-9


def test_loop_that_cannot_close_at_run_time(xz):
    """A coupler 1 m too long: the parallelogram cannot be assembled (no silent NaN or clip)."""
    with _raises(LoopClosureError, "parallelogram"):
        xz.fk("worst", deltas={"hp3": 1000.0})
    with _raises(LoopClosureError, "parallelogram"):
        xz.sensitivity("worst", deltas={"hp4": -279.0, "hp2": 300.0})


# ---------------------------------------------------------------------------------------------
# malformed model files
# ---------------------------------------------------------------------------------------------
def _write(tmp_path, source_model, edits, name="broken.toml"):
    text = (MODELS_DIR / f"{source_model}.toml").read_text()
    for pattern, replacement in edits:
        new = re.sub(pattern, replacement, text, count=1, flags=re.M)
        assert new != text, f"edit {pattern!r} did not apply"
        text = new
    path = tmp_path / name
    path.write_text(text)
    return path


MALFORMED = [
    # (source model, [(regex, replacement)], field named in the message, other fragments)
    ("planar_2r", [(r"^source = .*\n", "")], "model.source", ["missing"]),
    ("planar_2r", [(r'^length = "mm"', "# no length unit")], "units.length", ["missing"]),
    ("planar_2r", [(r'^length = "mm"', 'length = "furlong"')], "units.length", ["unknown unit", "furlong"]),
    ("planar_2r", [(r'^unit = "mrad"', 'unit = "milliradian"')], "error_parameters[2].unit", ["unknown unit"]),
    ("planar_2r", [(r'^unit = "mm"', 'unit = "mrad"')], "error_parameters[0].unit", ["not a unit of length"]),
    ("planar_2r", [(r"^k = 1.0\n", "")], "error_parameters[0].k", ["missing"]),
    ("planar_2r", [(r'alpha = "alpha1" \}', 'alpha = "l1" }')], "chain.links[0].alpha", ["'l1'", "length", "angle"]),
    ("planar_2r", [(r'a = "l1", alpha', 'a = "l1", h = "l1", alpha')], "chain.links[0].h", ["'h'", "standard"]),
    ("xu_zhang_1988", [(r'alpha = "alpha0"', 'alpha = "alpha0", d = "s1"')], "chain.links[0].d", ["'d'", "modified"]),
    ("planar_2r", [(r'^convention = "standard"', 'convention = "craig"')], "chain.convention", ["craig"]),
    ("planar_2r", [(r"^limits = \[-170.0, 170.0\]", "limits = [170.0, -170.0]")], "joints[0].limits", ["below"]),
    ("planar_2r", [(r"^l1 = 0.05", "l1 = -0.05")], "tolerance_sets.coarse.l1", [">= 0"]),
    ("planar_2r", [(r"^q2 = 90.0", "q3 = 90.0")], "configurations.elbow90.q3", ["did you mean `q"]),
    ("planar_2r", [(r'perturbs = \["l2"\]', 'perturbs = ["l3"]')], "error_parameters[1].perturbs[0]", ["'l3'"]),
    ("planar_2r", [(r"^\[symbols\]", "[symbols\n")], "(file)", ["TOML"]),
    ("xu_zhang_1988", [(r"^hp3 = 600.0", "hp3 = 2000.0")], "loops.parallelogram", ["cannot close", "'worst'"]),
    ("xu_zhang_1988", [(r"^hp4 = 280.0", "hp4 = -280.0")], "loops.parallelogram.lever", ["> 0"]),
    ("xu_zhang_1988", [(r'^crank_angle = "thetap2"', 'crank_angle = "theta9"')], "loops[0].crank_angle", ["theta9"]),
]


@pytest.mark.parametrize("source, edits, field, fragments", MALFORMED, ids=[m[2] for m in MALFORMED])
def test_malformed_model_file(tmp_path, source, edits, field, fragments):
    path = _write(tmp_path, source, edits)
    with _raises(ModelFileError, field, *fragments) as info:
        tolsynth.load_model(path)
    assert info.value.field == field
    assert str(path) in str(info.value)


def test_unmodified_copies_load(tmp_path):
    """The edits above are the only defect: the same files copied unmodified load and agree."""
    for name in ("planar_2r", "xu_zhang_1988"):
        path = tmp_path / f"{name}.toml"
        path.write_text((MODELS_DIR / f"{name}.toml").read_text())
        m = tolsynth.load_model(path)
        q = next(iter(m.configurations.values()))
        ref = planar_fk(q) if name == "planar_2r" else xu_fk(q)
        assert np.max(np.abs(m.fk(q) - ref)) < 1e-9


def test_poses_may_mix_names_and_joint_vectors(xz):
    """A list mixing a configuration name and a joint vector is valid (it raised numpy's ValueError):
    the optimum equals the one with both poses as joint vectors."""
    import tolsynth

    a = tolsynth.synthesize(xz, R=0.5, p=0.9, poses=["worst", xz.joints("home")], probability="gaussian")
    b = tolsynth.synthesize(xz, R=0.5, p=0.9, poses=[xz.joints("worst"), xz.joints("home")], probability="gaussian")
    assert a.success and b.success and abs(a.cost - b.cost) <= 1e-7 * b.cost
    with _raises(InputError, "poses"):
        tolsynth.synthesize(xz, R=0.5, p=0.9, poses={"worst": 1}, probability="gaussian")


def test_every_entry_point_takes_a_model_name_and_types_anything_else():
    """A bundled model's name works wherever a Mechanism does (monte_carlo raised AttributeError on
    one); anything else is an InputError naming the argument."""
    mc = tolsynth.monte_carlo("planar_2r", "elbow90", "coarse", R=0.5, n=20_000, seed=1)
    assert 0.0 <= mc.p_sphere <= 1.0 and mc.n == 20_000
    w = tolsynth.worst_pose("planar_2r", "coarse", grid=4, starts=1)
    assert w.model == "planar_2r" and np.isfinite(w.value)
    for fn, args, kw in [
        (tolsynth.monte_carlo, (5, "elbow90", {"*": 0.01}), dict(R=0.5, n=1000)),
        (tolsynth.synthesize, (3.0, 0.5, 0.9), {}),
        (tolsynth.validate, (object(), {"*": 0.01}), dict(R=0.5, p=0.9, n=1000)),
        (tolsynth.worst_pose, (None, {"*": 0.01}), {}),
        (tolsynth.probability_map, (["planar_2r"],), {}),
    ]:
        with pytest.raises(InputError, match="mechanism"):
            fn(*args, **kw)


def test_dict_arguments_name_the_entry_and_take_unit_suffixes():
    """An unknown name in bounds, k or locks is an error naming that entry (bounds[length]); a bound
    written with a unit is converted into the parameter's tolerance unit (1 um = 0.001 mm, planar_2r's
    l1 in mm), one of the wrong kind is refused."""
    m = tolsynth.load_model("planar_2r")
    spec = dict(R=0.5, p=0.99, pose="elbow90", probability="gaussian")
    for kw, field in (
        (dict(bounds={"length": (0.001, 5.0)}), "bounds[length]"),
        (dict(k={"l3": 2.0}), "k[l3]"),
        (dict(locks={"zz": 0.1}), "locks[zz]"),
    ):
        with pytest.raises(UnknownNameError) as info:
            tolsynth.synthesize(m, **spec, **kw)
        assert info.value.field == field and "l1, l2, o1, o2" in str(info.value)
    r = tolsynth.synthesize(m, **spec, bounds={"l1": ("100um", "0.12mm")})
    assert (r.spec.lower[0], r.spec.upper[0]) == pytest.approx((0.1, 0.12), rel=1e-12)
    plain = tolsynth.synthesize(m, **spec, bounds={"l1": (0.1, 0.12)})
    assert r.cost == pytest.approx(plain.cost, rel=1e-12)
    with pytest.raises(InputError) as info:
        tolsynth.synthesize(m, **spec, bounds={"o1": ("1um", "5mm")})
    assert info.value.field == "bounds[o1].lower"


def test_partial_alpha_dict_keeps_the_default_for_the_others():
    """A dict alpha names only the parameters it changes, as k does: the others keep synthesize's
    default exponent (0.7, read from its signature; a model file has no alpha), so it solves the
    same problem as the full dict written out by hand; an unknown name is refused naming it."""
    import inspect

    m = tolsynth.load_model("planar_2r")
    spec = dict(R=0.5, p=0.99, pose="elbow90", probability="gaussian")
    default = inspect.signature(tolsynth.synthesize).parameters["alpha"].default
    assert default == 0.7
    partial = tolsynth.synthesize(m, **spec, alpha={"l1": 0.5})
    full = tolsynth.synthesize(m, **spec, alpha={"l1": 0.5, "l2": default, "o1": default, "o2": default})
    assert partial.spec.alpha.tolist() == [0.5, 0.7, 0.7, 0.7]
    assert partial.cost == pytest.approx(full.cost, rel=1e-12)
    assert partial.x == pytest.approx(full.x, rel=1e-12)
    uniform = tolsynth.synthesize(m, **spec)
    assert abs(partial.cost - uniform.cost) > 1e-3 * uniform.cost  # the one override took effect
    with pytest.raises(UnknownNameError) as info:
        tolsynth.synthesize(m, **spec, alpha={"l1": 0.5, "l3": 0.5})
    assert info.value.field == "alpha[l3]" and "l1, l2, o1, o2" in str(info.value)
