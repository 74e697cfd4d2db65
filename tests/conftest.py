"""Shared fixtures: built models and settled states are expensive, so they
are made once per session."""

from __future__ import annotations

import pytest

from ehm_drake.params import load_params


@pytest.fixture(scope="session")
def params():
    return load_params()


@pytest.fixture(scope="session")
def settled_default(params):
    from ehm_drake.simulation import settle

    return settle(params, variant="default")


@pytest.fixture(scope="session")
def settled_variants(params, settled_default):
    from ehm_drake.simulation import settle

    out = {"default": settled_default}
    for v in ("no-integrator", "high-stiffness"):
        out[v] = settle(params, variant=v)
    return out
