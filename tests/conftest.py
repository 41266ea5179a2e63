import pytest

from roadload.data import shared_data_dir


@pytest.fixture
def shared_data():
    """Path to ../shared/data; skips the test with a reason when it is absent."""
    path = shared_data_dir()
    if path is None:
        pytest.skip("needs the shared driving data (../shared/data or $ROADLOAD_DATA); not present on this machine")
    return path
