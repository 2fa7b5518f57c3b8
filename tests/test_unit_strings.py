"""The units rule (docs/units.md) where a caller writes tolerances, joint values, a Pareto sweep's R
or a DesignSpec: a string with a unit suffix is the number converted by hand (50 um = 0.05 mm,
500 urad = 0.5 mrad, 30 deg = pi/6 rad), giving the same result as the plain number; and the typed
errors of these arguments name the argument they came in and say what it takes."""

from __future__ import annotations

import math

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import InputError, UnknownNameError

GAUSS = dict(R=0.5, p=0.99, pose="elbow90", probability="gaussian")
#: planar_2r's tolerances (l1, l2 in mm; o1, o2 in mrad), plain and written with units
PLAIN = {"l1": 0.05, "l2": 0.05, "o1": 0.5, "o2": 0.5}
WITH_UNITS = {"l1": "50um", "l2": "0.005cm", "o1": "500urad", "o2": 0.5}


@pytest.fixture(scope="module")
def m2():
    return tolsynth.load_model("planar_2r")


def test_tolerance_dicts_and_vectors_take_unit_suffixes(m2):
    assert m2.units == ("mm", "mm", "mrad", "mrad")  # what the hand conversions above assume
    np.testing.assert_allclose(m2.tolerances(WITH_UNITS), [0.05, 0.05, 0.5, 0.5], rtol=1e-12)
    np.testing.assert_allclose(m2.tolerances(["50um", 0.05, "0.5mrad", "500urad"]), [0.05, 0.05, 0.5, 0.5], rtol=1e-12)
    a = tolsynth.monte_carlo(m2, "elbow90", WITH_UNITS, R=0.5, n=1000, seed=3)
    b = tolsynth.monte_carlo(m2, "elbow90", PLAIN, R=0.5, n=1000, seed=3)
    assert a.tolerances == pytest.approx(PLAIN, rel=1e-12)
    np.testing.assert_allclose(a.principal_std, b.principal_std, rtol=1e-12)
    # deltas in a parameter's tolerance unit too: 10 um on l1 moves the stretched hand 0.01 mm along x
    dx = m2.fk("stretched", {"l1": "10um"})[0, 3] - m2.fk("stretched")[0, 3]
    assert dx == pytest.approx(0.01, rel=1e-9)
    with pytest.raises(InputError) as info:  # a length for an angle parameter
        m2.tolerances({**PLAIN, "o1": "50um"})
    assert info.value.field == "tolerances[o1]" and "angle unit" in str(info.value)


def test_x0_takes_unit_suffixes_and_its_errors_name_x0(m2):
    plain = tolsynth.synthesize(m2, **GAUSS, solver="ipopt", x0=PLAIN)  # IPOPT starts from x0
    assert plain.inputs["x0"] == pytest.approx([0.05, 0.05, 0.5, 0.5], rel=1e-12)
    res = tolsynth.synthesize(m2, **GAUSS, solver="ipopt", x0=WITH_UNITS)
    assert res.inputs["x0"] == pytest.approx([0.05, 0.05, 0.5, 0.5], rel=1e-12)
    assert res.cost == pytest.approx(plain.cost, rel=1e-12)
    for x0, field in (
        ({**PLAIN, "l1": -1.0}, "x0[l1]"),
        ("nope", "x0"),
        ({"l1": 0.05}, "x0"),
        ({**PLAIN, "zz": 1}, "x0[zz]"),
    ):
        with pytest.raises(InputError) as info:
            tolsynth.synthesize(m2, **GAUSS, x0=x0)
        assert info.value.field == field


def test_joint_vectors_take_unit_suffixes_per_joint(m2):
    a = tolsynth.synthesize(m2, 0.5, 0.99, pose=[math.pi / 6, math.pi / 2], probability="gaussian")
    b = tolsynth.synthesize(m2, 0.5, 0.99, pose=["30deg", "90deg"], probability="gaussian")
    assert b.cost == pytest.approx(a.cost, rel=1e-12)
    np.testing.assert_allclose(b.spec.poses["#0"], [math.pi / 6, math.pi / 2], rtol=1e-15)
    mc = tolsynth.monte_carlo(m2, ["30deg", "1800arcmin"], "coarse", R=0.5, n=1000, seed=1)  # 1800' = 30 deg
    np.testing.assert_allclose(mc.q, [math.pi / 6, math.pi / 6], rtol=1e-15)
    with pytest.raises(InputError) as info:
        m2.joints(["30deg", "1mm"])
    assert info.value.field == "q[q2]" and "angle unit" in str(info.value)
    # a joint that slides takes lengths: the Stewart platform's struts, 604.8652 mm at home
    sg = tolsynth.load_model("stewart_gough")
    assert sg.joint_value_units == ("mm",) * 6
    np.testing.assert_allclose(sg.joints(["60.48652cm"] * 6), [604.8652] * 6, rtol=1e-12)
    with pytest.raises(InputError) as info:
        sg.joints(["1deg"] + ["604.8652mm"] * 5)
    assert info.value.field == "q[q1]" and "length unit" in str(info.value)


def test_pareto_front_takes_unit_suffixes_in_R_and_names_a_bad_one(m2):
    kw = dict(p=0.99, pose="elbow90", probability="gaussian")
    a = tolsynth.pareto_front(m2, R=[0.5, 1.0], **kw)
    b = tolsynth.pareto_front(m2, R=["500um", "1mm"], **kw)
    assert [r["R"] for r in b.rows] == pytest.approx([0.5, 1.0], rel=1e-12)
    assert [r["cost"] for r in b.rows] == pytest.approx([r["cost"] for r in a.rows], rel=1e-12)
    c = tolsynth.pareto_front(m2, R="0.05cm", p=[0.9, 0.99], pose="elbow90", probability="gaussian")
    assert c.rows[1]["R"] == pytest.approx(0.5, rel=1e-12) and c.rows[1]["cost"] == pytest.approx(a.rows[0]["cost"])
    with pytest.raises(InputError) as info:
        tolsynth.pareto_front(m2, R=["500um", "5deg"], **kw)
    assert info.value.field == "R[1]" and "length unit" in str(info.value)
    with pytest.raises(InputError) as info:
        tolsynth.pareto_front(m2, R=0.5, p=["high", 0.9], pose="elbow90")
    assert info.value.field == "p[0]"


def test_synthesize_workspace_refuses_poses_naming_its_starting_pose(m2):
    with pytest.raises(InputError) as info:
        tolsynth.synthesize_workspace(m2, R=0.5, p=0.99, poses=["elbow90"])
    assert info.value.field == "poses" and "pose=" in str(info.value)


@pytest.mark.parametrize("name", ["alpha", "k"])
@pytest.mark.parametrize("value", ["x", {"l1": "x", "l2": 1, "o1": 1, "o2": 1}, ["x", 1, 1, 1]])
def test_alpha_and_k_type_errors_say_what_they_take(m2, name, value):
    with pytest.raises(InputError) as info:
        tolsynth.synthesize(m2, **GAUSS, **{name: value})
    text = str(info.value)
    assert info.value.field in (name, f"{name}[l1]")
    assert f"1e-12 <= {name} <= {'10' if name == 'alpha' else '1e+09'}" in text
    assert ("exponent" if name == "alpha" else "factor") in text and "-1e+09" not in text


def test_unknown_name_in_a_distribution_dict_names_the_entry(m2):
    with pytest.raises(UnknownNameError) as info:
        tolsynth.synthesize(m2, **GAUSS, distribution={"zz": "normal"})
    assert info.value.field == "distribution[zz]" and "l1, l2, o1, o2" in str(info.value)


def test_design_spec_and_keyword_with_the_same_quantity_in_other_units_agree(m2):
    plain = tolsynth.synthesize(m2, **GAUSS)
    spec = tolsynth.DesignSpec(R="500um", p=0.99, pose="elbow90", probability="gaussian")
    for R in (0.5, "0.5mm", "0.05cm"):
        assert tolsynth.synthesize(m2, spec=spec, R=R).cost == pytest.approx(plain.cost, rel=1e-12)
    with pytest.raises(InputError) as info:  # 600 um is another value
        tolsynth.synthesize(m2, spec=spec, R=0.6)
    assert info.value.field == "R"
    oriented = tolsynth.DesignSpec(R=0.5, p=0.99, Phi="2mrad", pose="elbow90", probability="gaussian")
    a = tolsynth.synthesize(m2, spec=oriented, Phi=0.002)
    b = tolsynth.synthesize(m2, **GAUSS, Phi=0.002)
    assert a.cost == pytest.approx(b.cost, rel=1e-12)


def test_cost_models_and_processes_read_suffixed_tolerances_in_each_parameters_unit(m2):
    """A tabulated curve's tolerances and a process's range written with units are the numbers
    converted by hand into the parameter's tolerance unit (1 um = 0.001 mm; 0.05 deg = 0.8726...
    mrad), solving the same problem; a unit on a plain number (k, a cost) or of the wrong kind is
    refused naming the field, never read as another number."""
    table_mm = {"model": "tabulated", "eps": [0.001, 0.1, 5.0], "costs": [10.0, 3.0, 1.0]}
    table_units = {**table_mm, "eps": ["1um", "100um", "0.5cm"]}
    deg = 1000 * math.pi / 180  # mrad per degree
    angles = {"model": "tabulated", "eps": [0.001, 0.05 * deg, 50.0], "costs": [10.0, 3.0, 1.0]}
    angles_units = {**angles, "eps": ["1urad", "0.05deg", "0.05rad"]}
    plain = tolsynth.synthesize(m2, **GAUSS, cost={"l1": table_mm, "o1": angles})
    res = tolsynth.synthesize(m2, **GAUSS, cost={"l1": table_units, "o1": angles_units})
    assert res.spec.costs.models[0].eps == pytest.approx(table_mm["eps"], rel=1e-12)
    assert res.spec.costs.models[2].eps == pytest.approx(angles["eps"], rel=1e-12)
    assert res.cost == pytest.approx(plain.cost, rel=1e-12)
    for cost, field in (
        ({"l1": {"model": "power", "k": "2mm", "alpha": 0.7}}, "cost.k"),
        ({"l1": {**table_mm, "costs": ["10mm", 3.0, 1.0]}}, "cost.costs[0]"),
        ({"o1": {**angles, "eps": ["1um", 0.05 * deg, 50.0]}}, "cost.eps[0]"),  # a length for an angle
    ):
        with pytest.raises(InputError) as info:
            tolsynth.synthesize(m2, **GAUSS, cost=cost)
        assert info.value.field == field
    power = {"model": "power", "k": 1.0, "alpha": 0.7}
    by_hand = {"o1": [{"name": "a", "cost": power, "lower": 0.01 * deg, "upper": 1.0 * deg}]}
    written = {"o1": [{"name": "a", "cost": power, "lower": "0.01deg", "upper": "1deg"}]}
    a = tolsynth.synthesize_processes(m2, 0.5, 0.99, by_hand, pose="elbow90", probability="gaussian")
    b = tolsynth.synthesize_processes(m2, 0.5, 0.99, written, pose="elbow90", probability="gaussian")
    assert b.cost == pytest.approx(a.cost, rel=1e-12)
    assert b.result.x == pytest.approx(a.result.x, rel=1e-12)
    with pytest.raises(InputError) as info:  # a length for an angle parameter was read as mm
        tolsynth.synthesize_processes(
            m2, 0.5, 0.99, {"o1": [{**written["o1"][0], "lower": "50um"}]}, pose="elbow90", probability="gaussian"
        )
    assert info.value.field.endswith("process 'a'.lower") and "angle unit" in str(info.value)


def test_sweep_grid_file_reads_R_with_a_unit_and_refuses_one_on_p_or_alpha(tmp_path, capsys):
    """A grid file's R = "500um" is 0.5 mm; a unit on p or alpha (plain numbers) is an error."""
    from tolsynth.cli import main
    from tolsynth.cli.sweep import read_grid_file

    grid = tmp_path / "g.toml"
    grid.write_text('model = "planar_2r"\nR = ["500um", 0.3]\np = 0.99\n')
    assert read_grid_file(str(grid))["R"] == pytest.approx([0.5, 0.3], rel=1e-12)
    grid.write_text('model = "planar_2r"\nR = 0.5\np = 0.99\nalpha = "0.7mm"\n')
    assert main(["sweep", "--grid", str(grid), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "alpha" in err and "'0.7mm' has a unit" in err and "Traceback" not in err
