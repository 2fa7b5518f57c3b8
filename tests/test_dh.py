"""``tolsynth.Mechanism.from_dh``: a robot from a D-H table in Python.

References: the same robot loaded from its bundled model file (forward kinematics, sensitivities
and the synthesis optimum to 1e-9), and plain-NumPy D-H chains written here (the Puma 560 of
Corke & Armstrong-Helouvry 1994 and Universal Robots' UR5 table, typed in).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import InputError, ModelFileError, UnknownNameError

PI2 = math.pi / 2

# Puma 560 (Robotics Toolbox Puma560.py: d1 = 26.45 inch = 671.83 mm), mm and deg
PUMA_LINKS = [
    {"d": 671.83, "a": 0.0, "alpha": 90.0, "limits": (-160, 160)},
    {"d": 0.0, "a": 431.8, "alpha": 0.0, "limits": (-45, 225)},
    {"d": 150.05, "a": 20.3, "alpha": -90.0, "limits": (-225, 45)},
    {"d": 431.8, "a": 0.0, "alpha": 90.0, "limits": (-110, 170)},
    {"d": 0.0, "a": 0.0, "alpha": -90.0, "limits": (-100, 100)},
    {"d": 0.0, "a": 0.0, "alpha": 0.0, "limits": (-266, 266)},
]
PUMA_CONFIGS = {
    "qz": [0, 0, 0, 0, 0, 0],
    "qr": [0, 90, -90, 0, 0, 0],
    "qs": [0, 0, -90, 0, 0, 0],
    "qn": [0, 45, -180, 0, 45, 0],
}
# Universal Robots' UR5 table (m, rad), given in SI units to check the unit conversion
UR5_A = [0.0, -0.425, -0.39225, 0.0, 0.0, 0.0]
UR5_D = [0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823]
UR5_ALPHA = [PI2, 0.0, 0.0, PI2, -PI2, 0.0]


def puma():
    return tolsynth.Mechanism.from_dh(
        PUMA_LINKS, "standard", name="puma560", configurations=PUMA_CONFIGS, angle_unit="deg"
    )


def ur5_in_si():
    links = [
        {"a": a, "d": d, "alpha": al, "limits": (-2 * math.pi, 2 * math.pi)}
        for a, d, al in zip(UR5_A, UR5_D, UR5_ALPHA)
    ]
    return tolsynth.Mechanism.from_dh(
        links, name="ur5", length_unit="m", angle_unit="rad", configurations={"worst": [0, 0, 0, -PI2, 0, 0]}
    )


def ur5_in_mm():
    """UR's table in mm and deg, the units of models/ur5.toml (bit-identical symbols)."""
    a = [0.0, -425.0, -392.25, 0.0, 0.0, 0.0]
    d = [89.159, 0.0, 0.0, 109.15, 94.65, 82.3]
    alpha = [90.0, 0.0, 0.0, 90.0, -90.0, 0.0]
    links = [{"a": a[i], "d": d[i], "alpha": alpha[i], "limits": (-360, 360)} for i in range(6)]
    return tolsynth.Mechanism.from_dh(
        links, name="ur5", configurations={"worst": [0, 0, 0, -90, 0, 0]}, angle_unit="deg"
    )


def panda():
    """Franka's table (modified D-H, Craig's a/d names accepted), the flange as a named tool."""
    a = [0.0, 0.0, 0.0, 82.5, -82.5, 0.0, 88.0]
    d = [333.0, 0.0, 316.0, 0.0, 384.0, 0.0, 0.0]
    alpha = [0.0, -PI2, PI2, PI2, -PI2, PI2, PI2]
    lo = [-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973]
    hi = [2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973]
    links = [{"a": a[i], "d": d[i], "alpha": alpha[i], "limits": (lo[i], hi[i])} for i in range(7)]
    m = tolsynth.load_model("panda")
    return tolsynth.Mechanism.from_dh(
        links,
        "modified",
        name="panda",
        angle_unit="rad",
        tool=[("Tz", 107.0, "flange")],
        errors=["h*", "s[1-6]", "alpha*", "o*", "flange"],
        configurations={c: list(q) for c, q in m.configurations.items()},
    )


# ---------------------------------------------------------------------------------------------
# the same robot as its model file
# ---------------------------------------------------------------------------------------------
def _solve_cold(m, pose):
    """Synthesize from scratch (stated, though it is the default): a warm start from another solve
    of the same blocks would differ from a cold solve by up to 2e-7 relative in the tolerances
    (measured on panda: the optimum is met to the solver's tol)."""
    return tolsynth.synthesize(m, R=0.5, p=0.99, pose=pose, options={"warm_start": False}, probability="gaussian")


@pytest.mark.parametrize("build, name", [(puma, "puma560"), (ur5_in_mm, "ur5"), (panda, "panda")])
def test_from_dh_equals_the_model_file(build, name):
    m, ref = build(), tolsynth.load_model(name)
    assert m.error_parameters == ref.error_parameters
    assert m.units == ref.units and np.array_equal(m.k, ref.k)
    assert all(np.array_equal(a, b) for a, b in zip(m.bounds, ref.bounds))
    assert m.spec.symbols.keys() == ref.spec.symbols.keys()
    for k, v in ref.spec.symbols.items():
        assert m.spec.symbols[k] == pytest.approx(v, rel=1e-14, abs=1e-12), k
    rng = np.random.default_rng(11)
    lo = np.array([j.lower for j in ref.spec.joints])
    hi = np.array([j.upper for j in ref.spec.joints])
    for q in lo + (hi - lo) * rng.random((20, len(lo))):
        assert np.max(np.abs(m.fk(q) - ref.fk(q))) <= 1e-9
        assert np.max(np.abs(m.sensitivity(q) - ref.sensitivity(q))) <= 1e-9
    pose = "worst" if "worst" in ref.configurations else "qn"
    r1, r2 = _solve_cold(m, pose), _solve_cold(ref, pose)
    assert r1.success and r2.success
    assert r1.cost == pytest.approx(r2.cost, rel=1e-9)
    np.testing.assert_allclose(r1.x, r2.x, rtol=1e-9)


def test_from_dh_in_metres_and_radians():
    """UR's table as published (m, rad) is the bundled ur5 (mm, deg) after the unit conversion:
    FK and sensitivities to 1e-9 mm.  The symbols differ in the last bit (0.10915 m * 1000 is
    109.14999999999999 mm), which moves IPOPT's optimum within its tolerance: the cost agrees to
    1e-9 and the tolerances to 1e-6 relative (5e-8 measured)."""
    m, ref = ur5_in_si(), tolsynth.load_model("ur5")
    for k, v in ref.spec.symbols.items():
        assert m.spec.symbols[k] == pytest.approx(v, rel=1e-15, abs=1e-13), k
    rng = np.random.default_rng(12)
    for q in rng.uniform(-2 * math.pi, 2 * math.pi, (20, 6)):
        assert np.max(np.abs(m.fk(q) - ref.fk(q))) <= 1e-9
        assert np.max(np.abs(m.sensitivity(q) - ref.sensitivity(q))) <= 1e-9
    r1, r2 = _solve_cold(m, "worst"), _solve_cold(ref, "worst")
    assert r1.cost == pytest.approx(r2.cost, rel=1e-9)
    np.testing.assert_allclose(r1.x, r2.x, rtol=1e-6)


# ---------------------------------------------------------------------------------------------
# against independent NumPy chains
# ---------------------------------------------------------------------------------------------
def _dh_standard(q, a, d, alpha):
    T = np.eye(4)
    for qi, ai, di, al in zip(q, a, d, alpha):
        ct, st, ca, sa = math.cos(qi), math.sin(qi), math.cos(al), math.sin(al)
        T = T @ np.array(
            [
                [ct, -st * ca, st * sa, ai * ct],
                [st, ct * ca, -ct * sa, ai * st],
                [0.0, sa, ca, di],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
    return T


def test_puma_and_ur5_fk_against_numpy_chains():
    rng = np.random.default_rng(3)
    p = puma()
    a = [x["a"] for x in PUMA_LINKS]
    d = [x["d"] for x in PUMA_LINKS]
    al = [math.radians(x["alpha"]) for x in PUMA_LINKS]
    lo, hi = np.radians([x["limits"] for x in PUMA_LINKS]).T
    for q in lo + (hi - lo) * rng.random((30, 6)):
        assert np.max(np.abs(p.fk(q) - _dh_standard(q, a, d, al))) <= 1e-9
    u = ur5_in_si()
    for q in rng.uniform(-2 * math.pi, 2 * math.pi, (30, 6)):
        T = _dh_standard(q, UR5_A, UR5_D, UR5_ALPHA)
        T[:3, 3] *= 1000.0  # m -> mm: the mechanism works in mm
        assert np.max(np.abs(u.fk(q) - T)) <= 1e-9


def test_sensitivity_of_from_dh_against_central_differences():
    """A base, a tool and an offset, with tolerances in um and deg: columns per tolerance unit."""
    m = tolsynth.Mechanism.from_dh(
        [
            {"d": 100.0, "a": 50.0, "alpha": 90.0, "offset": 10.0, "limits": (-180, 180)},
            {"a": 300.0, "limits": (-180, 180)},
            {"a": 200.0, "alpha": -90.0, "limits": (-180, 180)},
        ],
        base=[("Tz", 400.0), ("Rx", 5.0)],
        tool=[("Tx", 30.0)],
        tolerance_units={"length": "um", "angle": "deg"},
        bounds={"length": (1, 5000), "angle": (0.001, 3)},
        angle_unit="deg",
    )
    assert m.error_parameters[:2] == ("base1", "base2") and m.error_parameters[-1] == "tool1"
    q = np.radians([20.0, -35.0, 50.0])
    S = m.sensitivity(q)
    h = 1e-3
    for i, name in enumerate(m.error_parameters):
        Tp, Tm = m.fk(q, {name: h}), m.fk(q, {name: -h})
        col = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
        assert np.allclose(S[:3, i], col, rtol=1e-6, atol=1e-9), name
    # 1 um of a link length moves the hand by 1e-3 mm along that link's x axis
    assert np.linalg.norm(S[:3, m.index("a2")]) == pytest.approx(1e-3, rel=1e-12)


# ---------------------------------------------------------------------------------------------
# bad input: typed errors naming the field
# ---------------------------------------------------------------------------------------------
GOOD = [{"a": 100.0, "limits": (-90, 90)}, {"a": 50.0, "limits": (-90, 90)}]


def _links(i, **change):
    links = [dict(x) for x in GOOD]
    links[i].update(change)
    return links


@pytest.mark.parametrize(
    "kwargs, error, field",
    [
        ({"links": _links(1, a="long")}, ModelFileError, "links[1].a"),
        ({"links": _links(0, a=math.nan)}, ModelFileError, "links[0].a"),
        ({"links": _links(0, limits=(90, -90))}, ModelFileError, "links[0].limits"),
        ({"links": _links(1, limits=(1, 2, 3))}, ModelFileError, "links[1].limits"),
        ({"links": _links(1, lenght=3.0)}, UnknownNameError, "links[1].lenght"),
        ({"links": _links(0, h=3.0)}, UnknownNameError, "links[0].h"),  # h is the modified convention's
        # no limits: the model-file parser's missing field, as a model file's joint without limits
        ({"links": [GOOD[0], {"a": 1.0}]}, ModelFileError, "links[1].limits"),
        ({"links": [GOOD[0], 5.0]}, InputError, "links[1]"),
        ({"links": []}, InputError, "links"),
        ({"links": GOOD, "convention": "craig"}, InputError, "convention"),
        ({"links": GOOD, "length_unit": "inch"}, ModelFileError, "units.length"),
        ({"links": GOOD, "k": {"a2": -1.0}}, ModelFileError, "k[a2]"),
        ({"links": GOOD, "k": {"a9": 1.0}}, UnknownNameError, "k[a9]"),
        ({"links": GOOD, "bounds": {"angle": (0.0, 1.0)}}, ModelFileError, "bounds[alpha1]"),
        ({"links": GOOD, "tolerance_units": {"length": "mrad"}}, ModelFileError, "tolerance_units[a1]"),
        ({"links": GOOD, "errors": ["b*"]}, UnknownNameError, "errors[0]"),
        ({"links": GOOD, "configurations": {"home": [0.0]}}, InputError, "configurations[home]"),
        ({"links": GOOD, "configurations": {"home": {"q1": 0.0, "q3": 1.0}}}, ModelFileError, "configurations[home]"),
        ({"links": GOOD, "base": [("Tw", 1.0)]}, InputError, "base[0]"),
        ({"links": GOOD, "tool": [("Tz", "x")]}, ModelFileError, "tool[0]"),
        ({"links": [dict(GOOD[0], name="j"), dict(GOOD[1], name="j")]}, ModelFileError, "joints"),
    ],
)
def test_bad_input_is_a_typed_error_naming_the_field(kwargs, error, field):
    with pytest.raises(error) as info:
        tolsynth.Mechanism.from_dh(**{"angle_unit": "deg", **kwargs})
    assert info.value.field.startswith(field), (info.value.field, str(info.value))
    assert field in str(info.value)


def test_modified_convention_rejects_both_a_and_h():
    with pytest.raises(InputError, match=r"links\[0\]\.h"):
        tolsynth.Mechanism.from_dh([{"a": 1.0, "h": 1.0, "limits": (-1, 1)}], "modified")


def test_default_bounds_are_physical_in_any_tolerance_unit():
    """The default bounds 0.001-5 mm and 0.001-50 mrad read 1-5000 um and 0.001-50 mrad in deg
    when the tolerances are in um and deg; the optimum is then the one of the same arm in mm and
    mrad whose cost factors are rescaled by hand so that k eps^-alpha is the same cost:
    k_um (1000 eps_mm)^-alpha = (k_um 1000^-alpha) eps_mm^-alpha, and likewise for deg."""
    links = [{"a": 500.0, "limits": (-170, 170)}, {"a": 300.0, "limits": (-150, 150)}]
    kw = dict(angle_unit="deg", configurations={"p": [30, 90]})
    um = tolsynth.Mechanism.from_dh(links, tolerance_units={"length": "um", "angle": "deg"}, **kw)
    deg = 180.0 / math.pi * 1e-3  # one mrad in deg
    for p in um.parameters:
        lo, hi = (1.0, 5000.0) if p.kind == "length" else (0.001 * deg, 50.0 * deg)
        assert (p.lower, p.upper) == (pytest.approx(lo, rel=1e-12), pytest.approx(hi, rel=1e-12)), p.name
    alpha = 0.7
    ref = tolsynth.Mechanism.from_dh(links, k={"length": 1000.0**-alpha, "angle": 1.5 * deg**-alpha}, **kw)
    spec = dict(R=0.5, p=0.99, pose="p", alpha=alpha, probability="gaussian")
    a, b = tolsynth.synthesize(um, **spec), tolsynth.synthesize(ref, **spec)
    assert a.success and b.success
    assert a.cost == pytest.approx(b.cost, rel=1e-6)
    for p in um.parameters:
        to_ref = 1e-3 if p.kind == "length" else 1.0 / deg  # um -> mm, deg -> mrad
        assert a.tolerances[p.name] * to_ref == pytest.approx(b.tolerances[p.name], rel=1e-4), p.name
    # the lengths are not held at an upper bound (5 um was the bound before it was physical)
    assert all(a.tolerances[n] < 0.99 * 5000.0 for n in ("a1", "a2"))
    # given bounds stay in the tolerance unit, as given
    given = tolsynth.Mechanism.from_dh(
        links, tolerance_units={"length": "um"}, bounds={"length": (2.0, 40.0)}, errors=["a1", "a2"], **kw
    )
    assert [(p.lower, p.upper) for p in given.parameters] == [(2.0, 40.0), (2.0, 40.0)]
