"""Shared fixtures: built models and settled states are expensive, so they
are made once per session."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

from ehm_drake.params import load_params

# The gap diagnosis caches its linear model families (keyed by the model's
# source code and parameters, so a stale entry is never reused).  All test
# processes (and the notebooks' kernels, which inherit the environment) share
# one cache; the first builder holds a lock, the others wait for it.
os.environ.setdefault("EHM_DRAKE_CACHE",
                      str(Path(tempfile.gettempdir()) / "ehm_drake_test_cache"))


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
