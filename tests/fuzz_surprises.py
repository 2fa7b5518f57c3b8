"""Fuzz cases of the first-day surprises (registered into ``fuzz_cases.API_CASES``): URDF files
and load_urdf arguments, the limits of the budget and process searches, progress and exact
options, unit strings for R and Phi, and time limits.  The invariant is ``fuzz_cases``': ok with
checked numbers, or a typed error naming its field; a defect that must be rejected and is
accepted is ``Silent``."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

import tolsynth
from fuzz_cases import BAD, BadNumbers, Silent, _check_synthesis, finite

TWO = """
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
  <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<joint name="j2" type="revolute"><parent link="l1"/><child link="tip"/>
  <origin xyz="0.3 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
"""
#: (edit of the two-joint URDF, must it be rejected?)
URDF_EDITS = [
    (lambda t: t.replace('<axis xyz="0 0 1"/>', '<axis xyz="1 0"/>', 1), True),
    (lambda t: t.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>', 1), True),
    (lambda t: t.replace('<axis xyz="0 0 1"/>', '<axis xyz="1e308 1e308 1e308"/>', 1), True),
    (lambda t: t.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 1e-300"/>', 1), True),
    (lambda t: t.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 5"/>', 1), False),
    (lambda t: t.replace('xyz="0.3 0 0"', 'xyz="1e308 0 0"'), True),
    (lambda t: t.replace('xyz="0.3 0 0"', 'xyz="inf 0 0"'), True),
    (lambda t: t.replace('xyz="0.3 0 0"', 'xyz="0.3 0"'), True),
    (lambda t: t.replace('rpy="0 0 0"', 'rpy="nan 0 0"', 1), True),
    (lambda t: t.replace('rpy="0 0 0"', 'rpy="1e300 0 0"', 1), True),
    (lambda t: t + '<joint name="j3" type="fixed"><parent link="tip"/><child link="l1"/></joint>', True),
    (lambda t: t + '<joint name="j2" type="fixed"><parent link="tip"/><child link="t2"/></joint>', True),
    (lambda t: t.replace('lower="-3" upper="3"', 'lower="3" upper="-3"', 1), True),
    (lambda t: t.replace('lower="-3"', 'lower="nan"', 1), True),
    (lambda t: t.replace('type="revolute"', 'type="continuous"', 1), False),
    (lambda t: t.replace('type="revolute"', 'type="floating"', 1), True),
    (lambda t: t.replace("</joint>", "", 1), True),
    (lambda t: t, False),
]


_FOLDER: list[Path] = []


def _urdf_file(text: str, extra_links: str = "") -> Path:
    """The robot written to one file of one temporary folder per process (overwritten each case)."""
    import re

    links = sorted(set(re.findall(r'link="([^"]+)"', text)))
    if not _FOLDER:
        _FOLDER.append(Path(tempfile.mkdtemp(prefix="tolsynth_fuzz_")))
    path = _FOLDER[0] / "robot.urdf"
    path.write_text(
        '<robot name="r">' + "".join(f'<link name="{n}"/>' for n in links) + extra_links + text + "</robot>"
    )
    return path


def case_urdf_files(draw):
    edit, must_reject = draw(st.sampled_from(URDF_EDITS))
    duplicate_link = draw(st.booleans()) and draw(st.booleans())

    def run():
        path = _urdf_file(edit(TWO), '<link name="l1"/>' if duplicate_link else "")
        m = tolsynth.load_urdf(path, "base", "tip")
        if must_reject or duplicate_link:
            raise Silent("a malformed URDF was accepted")
        finite(m.fk("zero"), m.sensitivity("zero"))
        res = tolsynth.synthesize(m, 0.5, 0.99, pose="zero")
        _check_synthesis(m, res, 0.5, 0.99, "uniform", ["zero"])

    return run


def case_load_urdf_arguments(draw):
    name = draw(
        st.sampled_from(
            [
                "errors",
                "configurations",
                "tolerance_sets",
                "assumptions",
                "name",
                "k",
                "bounds",
                "angle_unit",
                "length_unit",
                "base_link",
            ]
        )
    )
    pool = {
        "errors": [5, [5], "*.zz", ["*.xyz"], "all", None],
        "configurations": [
            "abc",
            {"a": "x"},
            {"a": [0.1, 0.2]},
            {"a": [90.0, 0.0]},
            {"a": [5.0, 0.0]},
            {"a": {"j1": 0.1, "j2": 0.2}},
            {"a": [math.nan, 0.0]},
            [1, 2],
        ],
        "tolerance_sets": ["x", {"s": 3}, {"s": {"j1.x": 0.1}}, {"s": {"zz": 0.1}}],
        "assumptions": [5, "text", ["a"], [5]],
        "name": [5, "r2", ""],
        "k": ["a", -1.0, {"length": 2.0}],
        "bounds": [5, (1.0, 0.5), (0.001, 1.0)],
        "angle_unit": ["deg", "furlong", 5, "rad"],
        "length_unit": ["m", "inch", None],
        "base_link": [5, "nope", "l1"],
    }
    value = draw(st.sampled_from(pool[name] + list(BAD[:6])))

    def run():
        path = _urdf_file(TWO)
        if name == "base_link":
            m = tolsynth.load_urdf(path, value, "tip")
        else:
            m = tolsynth.load_urdf(path, "base", "tip", **{name: value})
        for cname in m.configurations:
            finite(m.fk(cname))
            m.joints(cname)  # every named pose inside its limits (checked at load)

    return run


def case_search_limits(draw):
    """Limits of the budget and process searches, progress, exact options, time limits."""
    which = draw(
        st.sampled_from(["rtol", "max_solves", "max_nodes", "rel_gap", "progress", "exact_options", "time_limit"])
    )
    value = draw(st.sampled_from(list(BAD) + [{"bogus": 1}, "a", {"max_rounds": 2}, "x", True, 2, 1e-3]))
    m = tolsynth.load_model("planar_2r")

    def run():
        if which in ("rtol", "max_solves"):
            out = tolsynth.best_accuracy(m, 20.0, p=0.99, pose="elbow90", **{which: value})
            finite(out.value, out.bracket)
            if which == "rtol" and not (isinstance(value, (int, float)) and 0 < value <= 1):
                raise Silent(f"rtol={value!r} accepted")
        elif which in ("max_nodes", "rel_gap"):
            from tolsynth.model.cost import PowerLaw
            from tolsynth.synthesis.processes import Process

            procs = {
                "l1": [
                    Process("turning", PowerLaw(1.0, 0.7), 0.05, 0.5),
                    Process("grinding", PowerLaw(3.0, 0.7), 0.005, 0.05),
                ]
            }
            best = tolsynth.synthesize_processes(m, 0.5, 0.99, processes=procs, pose="elbow90", **{which: value})
            finite(best.cost, best.lower_bound)
            if best.proven and which == "max_nodes" and isinstance(value, (int, float)) and value < 2:
                raise Silent(f"max_nodes={value!r} reported a proven optimum")
        elif which == "progress":
            df = tolsynth.sweep(m, [0.5], 0.99, pose="elbow90", progress=value, client="serial")
            if not (value is None or isinstance(value, bool) or callable(value)):
                raise Silent(f"progress={value!r} accepted")
            finite(df["cost"].to_numpy())
        elif which == "exact_options":
            res = tolsynth.synthesize(m, 0.5, 0.99, pose="elbow90", probability="exact", options=value, time_limit=30)
            if not isinstance(value, dict) and value is not None:
                raise Silent(f"options={value!r} accepted")
            finite(res.cost)
        else:
            res = tolsynth.synthesize(m, 0.5, 0.99, pose="elbow90", time_limit=value)
            if res.success:
                _check_synthesis(m, res, 0.5, 0.99, "uniform", ["elbow90"])
            elif str(res.status) not in ("time_limit",):
                raise BadNumbers(f"status {res.status} at time_limit={value!r}")

    return run


def case_unit_strings(draw):
    """R and Phi written with units: the same numbers as the plain ones, or a typed error."""
    text = draw(
        st.sampled_from(
            [
                "500um",
                "0.5mm",
                "0.05cm",
                "0.0005m",
                " 0.5 mm",
                "5deg",
                "0.5 furlong",
                "",
                "mm",
                "1e400um",
                "nan mm",
                "-0.5mm",
                "0.5µm",
                "2mrad",
            ]
        )
    )
    m = tolsynth.load_model("planar_2r")

    def run():
        a = m.analyze("elbow90", "coarse", R=text)
        ref = {"500um": 0.5, "0.5mm": 0.5, "0.05cm": 0.5, "0.0005m": 0.5, " 0.5 mm": 0.5, "0.5µm": 5e-4}
        if text not in ref:
            raise Silent(f"R={text!r} accepted")
        b = m.analyze("elbow90", "coarse", R=ref[text])
        if not np.isclose(a.p_sphere, b.p_sphere, rtol=1e-12, atol=0):
            raise BadNumbers(f"R={text!r}: P {a.p_sphere} != {b.p_sphere}")

    return run


SURPRISE_CASES = {
    "URDF files": case_urdf_files,
    "load_urdf arguments": case_load_urdf_arguments,
    "search limits and options": case_search_limits,
    "unit strings": case_unit_strings,
}
