"""Shared fixtures: one OpenCL runtime for the whole run (PoCL on CI, a GPU where present)."""

import os

import pytest

os.environ.setdefault("POCL_AFFINITY", "0")


@pytest.fixture(scope="session")
def rt():
    from kernels import get_runtime

    return get_runtime()
