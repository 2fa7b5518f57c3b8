"""Cost models, processes and locks in model files: parsed strictly and used
by synthesize / synthesize_processes exactly as the same objects given through the API."""

from pathlib import Path

import pytest

import tolsynth
from tolsynth.model.cost import Chase, Exponential
from tolsynth.synthesis.processes import Process

BASE = (Path(tolsynth.__file__).resolve().parent.parent / "models" / "planar_2r.toml").read_text()


def _with(tmp_path, l1_extra: str, name="m.toml") -> Path:
    text = BASE.replace('name = "l1"\n', 'name = "l1"\n' + l1_extra, 1)
    path = tmp_path / name
    path.write_text(text)
    return path


def test_model_file_cost_processes_and_lock(tmp_path):
    path = _with(
        tmp_path,
        'cost = {model = "chase", A = 1.0, B = 0.4, k = 1.0}\n'
        'processes = [{name = "turning", cost = {model = "chase", A = 1.0, B = 0.4, k = 1.0}, lower = 0.1, upper = 1.0},\n'
        '             {name = "lapping", cost = {model = "exponential", A = 12.0, B = 20.0}, lower = 0.002, upper = 0.015}]\n',
    )
    m = tolsynth.load_model(path)
    assert m.cost_models == {"l1": Chase(1.0, 0.4, 1.0)}
    assert [p.name for p in m.processes["l1"]] == ["turning", "lapping"]
    api = tolsynth.synthesize("planar_2r", 0.5, 0.99, cost={"l1": Chase(1.0, 0.4, 1.0)}, probability="gaussian")
    fromfile = tolsynth.synthesize(m, 0.5, 0.99, probability="gaussian")
    assert fromfile.cost == pytest.approx(api.cost, rel=1e-9)
    procs = {
        "l1": [
            Process("turning", Chase(1.0, 0.4, 1.0), 0.1, 1.0),
            Process("lapping", Exponential(12.0, 20.0), 0.002, 0.015),
        ]
    }
    a = tolsynth.synthesize_processes("planar_2r", 0.2, 0.99, procs, probability="gaussian")
    b = tolsynth.synthesize_processes(m, 0.2, 0.99, probability="gaussian")
    assert a.processes == b.processes and a.cost == pytest.approx(b.cost, rel=1e-9)
    locked = tolsynth.load_model(_with(tmp_path, "lock = 0.05\n", "l.toml"))
    assert locked.locks == {"l1": 0.05}
    assert tolsynth.synthesize(locked, 0.5, 0.99, probability="gaussian").tolerances["l1"] == 0.05


@pytest.mark.parametrize(
    "extra, match",
    [
        ('cost = {model = "cubic"}\n', "cost.model"),
        ('cost = {model = "power", k = 1.0}\n', "missing"),
        ("lock = -1.0\n", "lock"),
        ('processes = [{name = "t", lower = 0.1, upper = 1.0}]\n', "cost"),
        ("costs = 1\n", "costs"),
    ],
)
def test_model_file_bad_designer_fields(tmp_path, extra, match):
    with pytest.raises(tolsynth.ModelFileError, match=match):
        tolsynth.load_model(_with(tmp_path, extra))
