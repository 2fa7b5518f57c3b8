"""tolsynth.sweep: rows checked against individual synthesize calls, on every
engine (this process, local processes, a dask.distributed.LocalCluster started here); a failed
solve is a row; bad grids are typed errors before any work."""

from __future__ import annotations

import json

import numpy as np
import pytest

import tolsynth
import tolsynth.synthesis.sweeps as sweeps
from tolsynth.errors import InputError, OutOfRangeError, UnknownNameError

pd = pytest.importorskip("pandas")

GRID = dict(R=[0.3, 0.5, 1e-7], p=[0.9, 0.99], alpha=[0.7], distribution=["uniform", "normal"])


def _check_against_synthesize(df, mech):
    assert list(df["row"]) == list(range(len(df)))
    for _, row in df.iterrows():
        if row["R"] == 1e-7:  # no tolerances inside the bounds meet 0.1 um: an error row, the others kept
            assert row["status"] == "error" and not row["success"]
            assert row["error"].startswith("InfeasibleSpecificationError")
            assert np.isnan(row["cost"])
            continue
        ref = tolsynth.synthesize(
            mech,
            R=row["R"],
            p=row["p"],
            distribution=row["distribution"],
            alpha=row["alpha"],
            criterion=row["criterion"],
            solver=row["solver"],
            probability=row["probability"],  # the kind the sweep used, in its own column
        )
        # the sphere's design is met but not proven optimal (its problem is not known to be convex)
        proven = row["criterion"] == "components"
        assert row["status"] == str(ref.status) == ("optimal" if proven else "feasible") and row["error"] == ""
        assert bool(row["success"]) is proven
        assert row["cost"] == pytest.approx(ref.cost, rel=1e-8)
        if row["criterion"] == "components":  # certified; the sphere's bound is its relaxation's
            assert row["gap"] <= 1e-6 * row["cost"]
        got = row[["eps_" + n for n in mech.error_parameters]].to_numpy(dtype=float)
        # the cost is flat at the optimum (its error is quadratic in the tolerances' error): costs equal
        # to 1e-8 allow tolerances ~1e-5 apart
        np.testing.assert_allclose(got, ref.x, rtol=1e-4)


def test_sweep_serial_matches_synthesize(xz, tmp_path):
    df = tolsynth.sweep(xz, **GRID, client="serial", probability="gaussian")
    assert len(df) == 12 and df["success"].sum() == 8
    _check_against_synthesize(df, xz)
    assert df.attrs["inputs"]["grid"]["R"] == [1e-7, 0.3, 0.5]
    assert df.attrs["summary"]["failed"] == 4
    # written and read back with its inputs
    path = tolsynth.write_table(df, tmp_path / "sweep.csv")
    back = pd.read_csv(path)
    np.testing.assert_array_equal(back["cost"].to_numpy(), df["cost"].to_numpy())
    assert tolsynth.read_table(path).attrs["inputs"]["model"]["name"] == "xu_zhang_1988"


@pytest.mark.slow  # about 4 s: the default run stays under 4 minutes
def test_sweep_local_processes(xz):
    df = tolsynth.sweep(
        xz,
        R=[0.4, 1e-7],
        p=0.99,
        criterion=["components", "sphere"],
        client="processes",
        workers=2,
        probability="gaussian",
    )
    assert df.attrs["summary"]["engine"].startswith("processes")
    _check_against_synthesize(df, xz)


def test_sweep_auto_engine(xz, monkeypatch):
    """client=None: a small grid stays in this process; one that would take long goes to processes."""
    df = tolsynth.sweep(xz, R=[0.4, 0.5], p=[0.9, 0.99, 0.995], probability="gaussian")
    assert df.attrs["summary"]["engine"].startswith("auto (4 solves here") and len(df) == 6
    assert df.attrs["summary"]["engine"].endswith("then serial (this process)")
    monkeypatch.setattr(sweeps, "AUTO_PROCESSES_S", 0.0)
    df = tolsynth.sweep(xz, R=[0.4, 0.5, 1e-7], p=[0.9, 0.99], workers=2, probability="gaussian")
    assert "then processes (2 on this machine)" in df.attrs["summary"]["engine"]
    _check_against_synthesize(df, xz)


def test_sweep_on_dask_local_cluster(xz):
    distributed = pytest.importorskip("distributed")
    with (
        distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster,
        distributed.Client(cluster) as client,
    ):
        df = tolsynth.sweep(xz, **GRID, client=client, probability="gaussian")
        assert df.attrs["summary"]["engine"].startswith("dask")
        _check_against_synthesize(df, xz)
        # the scheduler's address works the same (the client is opened and closed by sweep)
        df2 = tolsynth.sweep(xz, R=0.5, p=[0.9, 0.99], client=cluster.scheduler_address, probability="gaussian")
        _check_against_synthesize(df2, xz)


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_sweep_on_dask_worker_processes(xz):
    """Two worker processes (the model is scattered to each), both solvers."""
    distributed = pytest.importorskip("distributed")
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster,
        distributed.Client(cluster) as client,
    ):
        df = tolsynth.sweep(
            xz, R=[0.5, 1e-7], p=[0.9, 0.99], solver=["ipopt", "sumt"], client=client, probability="gaussian"
        )
        _check_against_synthesize(df, xz)


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        (dict(R=[]), InputError, "R: empty list"),
        (dict(R=[0.5, -1.0]), OutOfRangeError, "R"),
        (dict(p=[0.9, 1.5]), OutOfRangeError, "p"),
        (dict(alpha=[0.7, 0.0]), OutOfRangeError, "alpha"),
        (dict(alpha=[{"h99": 0.5}]), UnknownNameError, r"alpha\[h99\]"),
        (dict(distribution=["uniform", "cauchy"]), InputError, "distribution"),
        (dict(criterion="box"), InputError, "criterion"),
        (dict(solver=["ipopt", "snopt"]), InputError, "solver"),
        (dict(client="threads"), InputError, "client"),
        (dict(client=3), InputError, "client"),
        (dict(workers=0), OutOfRangeError, "workers"),
        (dict(validate=100), InputError, "validate"),
        (dict(tolerance=0.1), InputError, "tolerance"),
        (dict(k={"nope": 1.0}), UnknownNameError, "nope"),
        (dict(R=[0.1] * 1001, p=[0.9] * 1000), OutOfRangeError, "grid"),
    ],
)
def test_sweep_bad_grids(xz, kwargs, error, match):
    args = dict(R=0.5, p=0.99)
    args.update(kwargs)
    with pytest.raises(error, match=match):
        tolsynth.sweep(xz, **{"client": "serial", **args})


@pytest.mark.parametrize("fmt", ["csv", "json", "parquet"])
def test_sweep_with_per_parameter_alpha_writes_every_format(tmp_path, fmt):
    pytest.importorskip("pyarrow")
    m = tolsynth.load_model("planar_2r")
    alpha = {"l1": 0.5, "l2": 0.7, "o1": 0.7, "o2": 0.9}
    df = tolsynth.sweep(
        m, R=[0.5, 1e-9], p=0.9, alpha=[0.7, alpha], client="serial", pose="elbow90", probability="gaussian"
    )
    ref = tolsynth.synthesize(m, 0.5, 0.9, alpha=alpha, pose="elbow90", probability="gaussian")
    assert df.loc[1, "cost"] == pytest.approx(ref.cost, rel=1e-8)
    back = tolsynth.read_table(tolsynth.write_table(df, tmp_path / f"s.{fmt}"))
    assert list(back["status"]) == ["optimal", "optimal", "error", "error"]
    np.testing.assert_array_equal(back["cost"].to_numpy(), df["cost"].to_numpy())  # NaN in the error rows
    assert json.loads(back.loc[1, "alpha"]) == alpha and back.attrs["summary"]["failed"] == 2


def _planar_2r_normal_lengths(tmp_path):
    """planar_2r with the two link lengths declared normal in the model file (the offsets uniform)."""
    from pathlib import Path

    text = (Path(__file__).parents[1] / "models" / "planar_2r.toml").read_text()
    for name in ("l1", "l2"):
        text = text.replace(f'name = "{name}"\n', f'name = "{name}"\ndistribution = "normal"\n', 1)
    path = tmp_path / "p2r_normal.toml"
    path.write_text(text)
    return tolsynth.load_model(path)


def test_sweep_default_distribution_is_the_model_files(tmp_path):
    from statistics import NormalDist

    mech = _planar_2r_normal_lengths(tmp_path)
    # the default, None given explicitly, and uniform asked for by name
    default = tolsynth.sweep(mech, R=[0.5], p=[0.9, 0.99], client="serial")
    df = tolsynth.sweep(mech, R=[0.5], p=[0.9, 0.99], distribution=[None, "uniform"], client="serial")
    assert list(default["cost"]) == list(df[df["distribution"] != '"uniform"']["cost"])
    for _, row in df.iterrows():
        asked = "uniform" if row["distribution"] == '"uniform"' else None
        ref = tolsynth.synthesize(mech, R=row["R"], p=row["p"], distribution=asked)
        assert row["cost"] == pytest.approx(ref.cost, rel=1e-9)
    # at p = 0.9 the x error dl1 + dl2 of the stretched arm is binding, in closed form for both shapes
    # (equal k and alpha: eps_l1 = eps_l2 = e): normal with 3 sigma = e, P(|N(0, 2 e^2 / 9)| <= R) = p;
    # uniform, the triangle of U1 + U2: 1 - (2 e - R)^2 / (4 e^2) = p
    R, p = 0.5, 0.9
    e_normal = 3 * R / (2**0.5 * NormalDist().inv_cdf((1 + p) / 2))
    e_uniform = R / (2 * (1 - (1 - p) ** 0.5))
    rows = df[df["p"] == p]
    normal, uniform = rows.iloc[0], rows.iloc[1]
    assert normal["eps_l1"] == pytest.approx(e_normal, rel=1e-5) and normal["eps_l2"] == pytest.approx(
        e_normal, rel=1e-5
    )
    assert uniform["eps_l1"] == pytest.approx(e_uniform, rel=1e-5)
    assert normal["cost"] < uniform["cost"]  # 6.549 against 7.875: the normal rows read normal


def test_cli_sweep_default_distribution_is_the_model_files(tmp_path, capsys):
    from tolsynth.cli import main

    mech = _planar_2r_normal_lengths(tmp_path)
    ref = tolsynth.synthesize(mech, R=0.5, p=0.99)
    assert (
        main(["sweep", "--model", str(tmp_path / "p2r_normal.toml"), "--R", "0.5", "--p", "0.99", "--json", "--quiet"])
        == 0
    )
    (row,) = json.loads(capsys.readouterr().out)["rows"]
    assert row["cost"] == pytest.approx(ref.cost, rel=1e-9)
