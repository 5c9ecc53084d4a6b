import numpy as np
import pytest

from pmdcid.synth import PAPER


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture
def paper_values():
    from pmdcid.simulate import neutral_values

    return {**neutral_values(), **PAPER}
