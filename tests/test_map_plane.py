"""The map's default plane: a planar mechanism's own plane, not the xz plane it never leaves the
x axis of.  For the planar 2R arm the reachable part of that plane is checked against the closed
form of its annulus (l1 = 500, l2 = 300 mm, |q2| <= 150 deg, |q1| <= 170 deg)."""

from __future__ import annotations

import math

import numpy as np

import tolsynth


def test_planar_2r_map_defaults_to_its_plane_and_its_annulus():
    m = tolsynth.load_model("planar_2r")
    pm = tolsynth.probability_map(m, "coarse", R=0.05, n=41, check_points=0, progress=False)
    assert pm.plane == "xy" and pm.offset == 0.0
    U, V = np.meshgrid(pm.u, pm.v)
    r, phi = np.hypot(U, V), np.degrees(np.arctan2(V, U))
    r_min = math.sqrt(500.0**2 + 300.0**2 + 2 * 500.0 * 300.0 * math.cos(math.radians(150.0)))  # 283.2 mm
    cell = max(pm.u[1] - pm.u[0], pm.v[1] - pm.v[0])
    reach = pm.reachable.reshape(U.shape)
    assert np.all((r[reach] >= r_min - 1e-6) & (r[reach] <= 800.0 + 1e-6))
    # every point of the right half of the annulus (away from its edges) is reached
    inside = (r >= r_min + cell) & (r <= 800.0 - cell) & (np.abs(phi) <= 90.0)
    assert inside.sum() > 100 and np.all(reach[inside])
    assert np.all(np.isfinite(pm.P.reshape(U.shape)[inside]))


def test_planar_3rrr_map_defaults_to_its_plane():
    m = tolsynth.load_model("planar_3rrr")
    pm = tolsynth.probability_map(m, "coarse", R=0.05, n=21, check_points=0, progress=False)
    assert pm.plane == "xy" and pm.offset == 0.0 and pm.reachable.sum() > 20
    # a spatial arm keeps the paper's plane
    assert tolsynth.probability_map(tolsynth.load_model("xu_zhang_1988"), n=11, progress=False).plane == "xz"


def test_a_plane_reached_nowhere_is_a_one_line_error(capsys):
    """The planar 2R's xz plane touches its reachable set along the x axis only: no grid point is
    reached (an even grid has no line at y = 0), which the CLI says in one line (exit 2) and the plotting function as a typed error."""
    import pytest

    from tolsynth.analysis.plot import plot_map
    from tolsynth.cli import main
    from tolsynth.errors import InputError

    assert main(["map", "--model", "planar_2r", "--R", "0.5", "--plane", "xz", "--n", "10"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--plane" in err[0] and "reachable" in err[0], err
    pm = tolsynth.probability_map(tolsynth.load_model("planar_2r"), "coarse", plane="xz", n=10, progress=False)
    assert not pm.reachable.any()
    with pytest.raises(InputError, match="nothing to draw"):
        plot_map(pm)


def test_map_to_dict_is_json_with_none_where_unreachable():
    """The unreachable grid points (P NaN) become None in to_dict, the reachable ones keep their
    value, and strict JSON (no NaN tokens) takes the dict."""
    import json

    pm = tolsynth.probability_map("planar_2r", "coarse", R=0.5, n=10)
    assert np.isnan(pm.P).any() and np.isfinite(pm.P).any()
    d = json.loads(json.dumps(pm.to_dict(), allow_nan=False))
    P = np.array([[np.nan if v is None else v for v in row] for row in d["P"]])
    assert np.array_equal(np.isnan(P), ~pm.reachable) and np.array_equal(P[pm.reachable], pm.P[pm.reachable])
