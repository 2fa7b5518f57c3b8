"""Strict model files: every defect is a ModelFileError naming the
file and the field, with the nearest valid name for a misspelt key.

Each case edits one bundled model (as a dict, written back as TOML) and asserts the field named;
the unmodified dict written the same way loads (``test_round_trip_loads``), so the edit is the
only defect.
"""

from __future__ import annotations

import copy
import math

import pytest

import tolsynth
from model_text import assert_defect_named, model_dict
from model_text import edited as _edit
from model_text import load_dict as _load
from model_text import set_at as _set
from tolsynth.errors import ModelFileError
from tolsynth.model.fields import FORMAT


def _rename(table, old, new):
    table[new] = table.pop(old)


def _dup_loop(d):
    d["loops"].append(copy.deepcopy(d["loops"][0]))


CASES = [
    # (model, edit, field named, fragment of the message)
    (
        "xu_zhang_1988",
        lambda d: _rename(d, "error_parameters", "error_parameter"),
        "error_parameter",
        "did you mean `error_parameters`?",
    ),
    ("planar_2r", lambda d: _rename(d["model"], "title", "titel"), "model.titel", "did you mean `title`?"),
    (
        "planar_2r",
        lambda d: _rename(d, "configurations", "configuration"),
        "configuration",
        "did you mean `configurations`?",
    ),
    (
        "planar_2r",
        _set(["error_parameters", 0, "bound"], [0.001, 1.0]),
        "error_parameters[0].bound",
        "did you mean `bounds`?",
    ),
    ("puma560", _set(["units", "lenght"], "mm"), "units.lenght", "did you mean `length`?"),
    ("xu_zhang_1988", _set(["loops", 0, "brnch"], 1), "loops[0].brnch", "did you mean `branch`?"),
    (
        "planar_2r",
        _set(["tolerance_sets", "coarse", "l1"], {"value": 1.0, "units": "mm"}),
        "tolerance_sets.coarse.l1.units",
        "did you mean `unit`?",
    ),
    ("planar_2r", _set(["configurations", "worst", "nots"], "x"), "configurations.worst.nots", "did you mean `note`?"),
    # types
    ("xu_zhang_1988", _set(["error_parameters", 0, "alias"], ["x1"]), "error_parameters[0].alias", "a list"),
    (
        "xu_zhang_1988",
        _set(["configurations", "worst", "waive"], [["interference"]]),
        "configurations.worst.waive[0]",
        "a list",
    ),
    ("planar_2r", _set(["tolerance_sets", "coarse"], "abc"), "tolerance_sets.coarse", "a string"),
    ("xu_zhang_1988", _set(["loops"], True), "loops", "a boolean"),
    ("xu_zhang_1988", _set(["joint_constraints"], True), "joint_constraints", "a boolean"),
    ("xu_zhang_1988", _set(["reference_results"], False), "reference_results", "a boolean"),
    ("xu_zhang_1988", _set(["reference_results", 0, "R"], "0.5"), "reference_results[0].R", "a string"),
    (
        "xu_zhang_1988",
        _set(["reference_results", 0, "tolerances", 0], [1]),
        "reference_results[0].tolerances[0]",
        "a list",
    ),
    ("planar_2r", _set(["model"], "planar"), "model", "a string"),
    ("planar_2r", _set(["joints", 0], 5), "joints[0]", "expected a table"),
    ("planar_2r", _set(["model", "assumptions"], "one"), "model.assumptions", "a string"),
    # duplicates
    (
        "planar_2r",
        _set(["error_parameters", 0, "perturbs"], ["l1", "l1"]),
        "error_parameters[0].perturbs",
        "more than once",
    ),
    ("xu_zhang_1988", _dup_loop, "loops", "more than once"),
    ("planar_2r", _set(["joints", 1, "name"], "q1"), "joints", "more than once"),
    ("xu_zhang_1988", _set(["joint_constraints", 0, "name"], "theta1"), "joint_constraints", "more than once"),
    ("xu_zhang_1988", _set(["error_parameters", 1, "alias"], "x1"), "error_parameters[1].alias", "used twice"),
    # numbers that make no sense
    ("planar_2r", _set(["joints", 0, "limits"], [-math.inf, math.inf]), "joints[0].limits[0]", "finite"),
    (
        "xu_zhang_1988",
        _set(["joint_constraints", 0, "terms", "theta2"], math.nan),
        "joint_constraints[0].terms.theta2",
        "finite",
    ),
    ("xu_zhang_1988", _set(["loops", 0, "crank_angle"], "theta2"), "loops[0].crank_angle", "ground_angle"),
    ("planar_2r", _set(["symbols", "l1"], 1e300), "symbols.l1", "1e+09"),
    ("planar_2r", _set(["error_parameters", 0, "k"], -1.0), "error_parameters[0].k", "1e-12"),
    ("planar_2r", _set(["error_parameters", 0, "bounds"], [1e-300, 1.0]), "error_parameters[0].bounds", "> 0"),
    ("xu_zhang_1988", _set(["reference_results", 0, "p"], 1.0), "reference_results[0].p", "1e-12 to 1"),
    ("planar_2r", _set(["configurations", "worst", "q1"], math.inf), "configurations.worst.q1", "finite"),
    # empty
    ("planar_2r", _set(["joints"], []), "joints", "at least one"),
    ("planar_2r", _set(["model", "name"], ""), "model.name", "non-empty"),
]


@pytest.mark.parametrize("model, edit, field, fragment", CASES, ids=[c[2] for c in CASES])
def test_defect_names_field(tmp_path, model, edit, field, fragment):
    err = assert_defect_named(tmp_path, model, edit, field, fragment)
    assert str(tmp_path / "m.toml") in str(err)


@pytest.mark.parametrize("model", tolsynth.bundled_models())
def test_round_trip_loads(tmp_path, model):
    """The writer of these tests loses nothing: an unmodified model written by it loads, with the
    same numbers as the bundled file."""
    m = _load(tmp_path, model_dict(model))
    ref = tolsynth.load_model(model)
    assert m.spec.symbols == ref.spec.symbols and m.error_parameters == ref.error_parameters


@pytest.mark.parametrize(
    "blob, fragment",
    [
        (b"\xff\xfe[model]\n", "UTF-8"),
        (b'[model]\nname = "\xe9"\n', "UTF-8"),
        (b"[model\n", "not valid TOML"),
        (b"", "missing required field"),
    ],
)
def test_bytes_that_are_not_a_model(tmp_path, blob, fragment):
    path = tmp_path / "m.toml"
    path.write_bytes(blob)
    with pytest.raises(ModelFileError, match=fragment):
        tolsynth.load_model(path)


def test_format_table_lists_every_key_the_bundled_models_use():
    """FORMAT is the one list of allowed keys: every key of every bundled table is in it."""
    for name in tolsynth.bundled_models():
        d = model_dict(name)
        parallel = "leg" in d  # a parallel robot's file (tolsynth.model.parallel)
        assert set(d) <= set(FORMAT["parallel" if parallel else ""])
        for section in ("model", "units", "platform") if parallel else ("model", "units", "chain"):
            assert set(d[section]) <= set(FORMAT[section])
        assert set(d.get("errors", {})) <= set(FORMAT["leg_errors"])
        for section in ("joints", "loops", "joint_constraints", "error_parameters", "reference_results", "leg"):
            for item in d.get(section, []):
                assert set(item) <= set(FORMAT[section]), (name, section)


@pytest.mark.parametrize(
    "model, edit, field, fragment",
    [
        (
            "planar_2r",
            _set(("configurations", "elbow90", "q2"), 160.0),
            "configurations.elbow90.q2",
            "160 deg is outside the joint limits -150 to 150 deg",
        ),
        (
            "planar_2r",
            _set(("configurations", "stretched", "q1"), -171.0),
            "configurations.stretched.q1",
            "outside the joint limits",
        ),
        ("xu_zhang_1988", _set(("configurations", "home", "waive"), []), "configurations.home", None),
    ],
)
def test_configurations_outside_the_limits_fail_at_load(tmp_path, model, edit, field, fragment):
    """A model file whose own named pose lies outside a joint limit (or breaks a joint constraint
    it does not waive) is refused when read, naming the configuration and joint, not at its
    first use."""
    data = _edit(model, edit)
    if fragment is None:  # the home pose of the paper's arm: inside every limit already
        _load(tmp_path, data)
        return
    with pytest.raises(ModelFileError) as info:
        _load(tmp_path, data)
    assert info.value.field == field and fragment in str(info.value)


def test_a_waived_limit_still_loads(tmp_path):
    """The paper's 'worst' pose lies 0.33 deg past the interference limit and says so ('waive' and a
    note): it loads; the same pose without the waiver is refused naming the constraint."""
    tolsynth.load_model("xu_zhang_1988")
    data = _edit("xu_zhang_1988", lambda d: d["configurations"]["worst"].pop("waive", None))
    with pytest.raises(ModelFileError) as info:
        _load(tmp_path, data)
    assert info.value.field == "configurations.worst" and "interference" in str(info.value)
