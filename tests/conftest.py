import warnings

import pytest

import paramimic.envs  # noqa: F401  (registers the gymnasium ids)


@pytest.fixture(autouse=True)
def _quiet_gymnasium_bounds():
    # gymnasium warns about infinite observation bounds, as for its own MuJoCo environments
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*Box observation space.*infinity")
        yield
