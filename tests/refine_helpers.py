"""What the refiner tests share: a tiny model size and one torch thread per test module."""

import pytest
import torch

from gesturekit.refine.model import ModelConfig

#: Generator and critic small enough to train in milliseconds.
TINY = ModelConfig(generator_channels=(4, 8, 8, 8), critic_channels=(8, 4, 4))


@pytest.fixture(autouse=True, scope="module")
def _one_torch_thread():
    # tiny networks: one thread is faster, and immune to a busy machine's thread contention
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)
