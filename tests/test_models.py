"""The bundled model files against the numbers their sources state.

The paper's robot (``xu_zhang_1988``): the worst-error pose puts the hand at (925, 0, 1225) mm
(the paper's section 5), and the position rows of the sensitivity match the table of
docs/reconstruction.md ("The worst-error pose"); the error parameters, cost factors and the Figure 3
tolerances are those of the paper's section 5.  ``puma560`` and ``planar_2r`` are checked against
hand-derived poses; ``ur5``'s reference pose against the certified worst pose its note names.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import tolsynth

# docs/reconstruction.md, position sensitivities at the worst pose (mm per mm, mm per rad), as printed
TABLE_COLUMNS = ["h2", "h3", "h4", "hp2", "hp3", "hp4", "s1", "a", "alpha1", "alpha3", "alpha4"]
TABLE = {
    "x": ["2.437", "0.925", "1.000", "-1.377", "-2.128", "1.377", "0", "0", "0", "0", "0"],
    "y": ["0", "0", "0", "0", "0", "0", "0", "0", "1025", "-138.7", "-150"],
    "z": ["-2.515", "0.380", "0", "2.243", "3.466", "-2.243", "1", "1", "0", "0", "0"],
}


def _half_ulp(text: str) -> float:
    """Half a unit of the last printed digit ('2.437' -> 5e-4, '1025' -> 0.5); a bare '0' is
    printed in a column of 3-decimal numbers, so it gets 5e-4 as well."""
    if text == "0":
        return 5e-4
    decimals = len(text.split(".")[1]) if "." in text else 0
    return 0.5 * 10.0**-decimals


def test_bundled_models_are_those_of_the_issues():
    """The three and the two real arms."""
    assert {"xu_zhang_1988", "puma560", "planar_2r", "ur5", "panda"} <= set(tolsynth.bundled_models())


def test_xu_worst_pose_hand_point(xz):
    """Hand at (925, 0, 1225) mm within 0.01 mm, by name and by the joint values; roll axis up
    (the paper's 'alpha = pi/2': the hand's z axis vertical)."""
    for q in ("worst", xz.configurations["worst"]):
        T = xz.fk(q)
        assert np.all(np.abs(T[:3, 3] - [925.0, 0.0, 1225.0]) <= 0.01), T[:3, 3]
        assert np.allclose(T[:3, 2], [0.0, 0.0, 1.0], atol=1e-8)
    # the reconstruction's joint values (theta1 = 180 deg there, 0 here with the 180 deg offset)
    expect_deg = [0.0, 157.645, 107.971, 22.355, 0.0]
    assert np.allclose(np.degrees(xz.configurations["worst"]), expect_deg, atol=5e-4)
    gamma = np.degrees(xz.configurations["worst"][1] - xz.configurations["worst"][2])
    assert abs(gamma - 49.674) < 5e-4  # 0.33 deg past the 50 deg interference limit


def test_xu_worst_pose_sensitivity_table(xz):
    """Position rows of the sensitivity vs the table of docs/reconstruction.md, to its rounding.

    The package's columns are per tolerance unit (mm; 1e-2 rad for alpha1, alpha3, alpha4), the
    table's per mm and per rad: the angle columns are divided by 0.01.  The y row is compared in
    magnitude (its sign depends on axis conventions)."""
    assert list(xz.error_parameters) == TABLE_COLUMNS
    S = xz.sensitivity("worst")
    per_table_unit = S[:3].copy()
    for j, name in enumerate(TABLE_COLUMNS):
        if name.startswith("alpha"):
            per_table_unit[:, j] /= 0.01
    worst = 0.0
    for r, row in enumerate("xyz"):
        for j, text in enumerate(TABLE[row]):
            value = per_table_unit[r, j]
            printed = float(text)
            if row == "y":
                value, printed = abs(value), abs(printed)
            assert abs(value - printed) <= _half_ulp(text), (row, TABLE_COLUMNS[j], value, text)
            worst = max(worst, abs(value - printed) / _half_ulp(text))
    print(f"table: largest deviation {worst:.2f} half-units of the last printed digit")


def test_xu_error_parameters_as_in_the_paper(xz):
    """x1..x11 in the paper's order, the cost factors k and the tolerance units of the paper's section 5."""
    assert [xz.parameters[xz.index(f"x{i}")].name for i in range(1, 12)] == TABLE_COLUMNS
    assert xz.k.tolist() == [1.0] * 8 + [1.5] * 3
    assert list(xz.units) == ["mm"] * 8 + ["1e-2 rad"] * 3
    by_name = {p.name: set(p.perturbs) for p in xz.parameters}
    assert by_name["h2"] == {"h2", "hp1"}  # one part: dh'1 = dh2


def test_xu_figure3_tolerances(xz):
    """Figure 3 half-tolerances (the paper's section 5, printed in mm and rad, listed there in the
    order dh'1(=dh2), dh'2, dh'3, dh'4, dh3, dh4, ds1, da, dalpha1, dalpha3, dalpha4), in the
    model's tolerance units: the angles 0.0005 rad = 0.05 x 1e-2 rad."""
    printed = dict(
        zip(
            ["h2", "hp2", "hp3", "hp4", "h3", "h4", "s1", "a", "alpha1", "alpha3", "alpha4"],
            [0.06, 0.028, 0.06, 0.028, 0.08, 0.01, 0.01, 0.015, 0.0005, 0.0005, 0.0005],
        )
    )
    expect = [printed[n] / (0.01 if n.startswith("alpha") else 1.0) for n in TABLE_COLUMNS]
    assert np.allclose(xz.tolerances("figure3"), expect, rtol=1e-12, atol=0)


def test_xu_joint_limits_as_printed(xz):
    """Ranges of the paper's section 5 (deg), and the interference limit 50 <= theta'2 - theta2 <= 130."""
    printed = {
        "theta1": (-150, 150),
        "thetap2": (140, 200),
        "theta2": (50, 130),
        "theta4": (-110, 110),
        "theta5": (-185, 185),
    }
    assert {j.name for j in xz.spec.joints} == set(printed)
    for j in xz.spec.joints:
        assert (math.degrees(j.lower), math.degrees(j.upper)) == pytest.approx(printed[j.name], abs=1e-12)
    (c,) = xz.spec.joint_constraints
    assert c.terms == {"thetap2": 1.0, "theta2": -1.0}
    assert (math.degrees(c.lower), math.degrees(c.upper)) == pytest.approx((50.0, 130.0))


def test_puma_parameters_and_poses():
    """Every a, d, alpha and joint offset is an error parameter; qz and qr by hand."""
    m = tolsynth.load_model("puma560")
    assert set(m.error_parameters) == {f"{k}{i}" for i in range(1, 7) for k in ("a", "d", "alpha", "o")}
    # qz: arm along X0, (a2 + a3, -d3, d1 + d4)
    assert np.allclose(m.fk("qz")[:3, 3], [431.8 + 20.3, -150.05, 26.45 * 25.4 + 431.8], atol=1e-9)
    # qr (q2 = 90, q3 = -90): link 2's x axis points up, so a2 rises; q3 = -90 turns link 3's x
    # back to +x0, so a3 runs along +x0, and d4 (along link 4's z, alpha3 = -90) rises again.
    assert np.allclose(m.fk("qr")[:3, 3], [20.3, -150.05, 26.45 * 25.4 + 431.8 + 431.8], atol=1e-9)


def test_planar_2r_poses():
    m = tolsynth.load_model("planar_2r")
    assert np.allclose(m.fk("stretched")[:3, 3], [800.0, 0.0, 0.0], atol=1e-12)
    t1, t2 = math.radians(30), math.radians(120)
    expect = [500 * math.cos(t1) + 300 * math.cos(t2), 500 * math.sin(t1) + 300 * math.sin(t2), 0.0]
    assert np.allclose(m.fk("elbow90")[:3, 3], expect, atol=1e-9)
    # joint offsets in mrad: at the stretched pose do1 = 1 mrad moves the hand 0.8 mm along y
    S = m.sensitivity("stretched")
    assert np.allclose(S[:3, m.error_parameters.index("o1")], [0.0, 0.8, 0.0], atol=1e-12)
    assert np.allclose(S[:3, m.error_parameters.index("l1")], [1.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.slow  # a certified search over five joints, about 10 s on two cores
def test_ur5_reference_pose_is_the_worst_of_the_fine_tolerances():
    """The UR5 file's note: 'worst' is the pose of largest sigma_1 (0.0672 mm, uniform errors) for
    the tolerance set 'fine'.  sigma_1 there from NumPy's eigenvalues; the largest over the whole
    joint space from the interval branch and bound, which must not exceed it by more than its
    tolerance."""
    from tolsynth.analysis.certify import certify_worst_pose

    m = tolsynth.load_model("ur5")
    eps = m.tolerances("fine")
    A = np.asarray(m.sensitivity("worst"))[:3]
    sigma = math.sqrt(np.linalg.eigvalsh((A * (eps**2 / 3.0)) @ A.T)[-1])
    assert round(sigma, 4) == 0.0672
    c = certify_worst_pose(m, "fine", distribution="uniform", progress=False)
    assert c.certified
    assert sigma <= c.upper_bound <= sigma * (1 + 1e-3)
