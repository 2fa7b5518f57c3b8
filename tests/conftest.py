"""Shared fixtures and the ``--runslow`` switch (slow tests are skipped by default, run in CI)."""

import os

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False, help="run tests marked slow")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow: run with --runslow (CI does)")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def xz():
    import tolsynth

    return tolsynth.load_model("xu_zhang_1988")


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)
