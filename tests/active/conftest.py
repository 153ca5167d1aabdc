import pytest
import torch


@pytest.fixture(autouse=True)
def single_thread():
    """Many tiny tensor ops: one intra-op thread is faster on a shared 2-core machine.
    Restored afterwards."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)
