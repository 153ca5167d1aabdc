"""Session fixtures: the tiny dataset and the tiny trained run (see tests/tiny_training.py)."""

import pytest

from tiny_training import tiny_dataset, tiny_run


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory):
    """Directory of a 6-object × 2-push dataset with 2 s pushes."""
    return tiny_dataset(tmp_path_factory)


@pytest.fixture(scope="session")
def tiny_run_dir(tmp_path_factory):
    """Run directory of a tiny vt-addf training on `tiny_data`."""
    return tiny_run(tmp_path_factory)
