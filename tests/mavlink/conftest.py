"""The MAVLink tests' shared fixture: no MAVSDK client outlives its test."""

import pytest

from .mavsdk_util import destroy_clients


@pytest.fixture(autouse=True)
def _no_client_outlives_its_test():
    yield
    destroy_clients()
