"""Shared fixtures and the switches of the two longer tiers: ``--runslow`` runs the tests marked
``slow`` (CI does), ``--runlong`` those marked ``long`` (minutes each: certified searches over
six-joint arms, the fuzz suite's long profile, hundreds of poses; run before a release, not in CI)."""

import os

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False, help="run tests marked slow")
    parser.addoption("--runlong", action="store_true", default=False, help="run tests marked long")


def pytest_collection_modifyitems(config, items):
    slow = pytest.mark.skip(reason="slow: run with --runslow (CI does)")
    long = pytest.mark.skip(reason="long: run with --runlong (before a release; not in CI)")
    for item in items:
        if "long" in item.keywords and not config.getoption("--runlong"):
            item.add_marker(long)
        elif "slow" in item.keywords and not config.getoption("--runslow"):
            item.add_marker(slow)


@pytest.fixture(scope="session")
def xz():
    import tolsynth

    return tolsynth.load_model("xu_zhang_1988")


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)
