"""[L21] Eq. 2-3 and Eq. 14 on hand-worked numbers."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paramimic.curriculum.elite_set import EliteRule, EliteSet
from paramimic.curriculum.knn_proxy import knn_proxy, knn_weights
from paramimic.motion.parameterization import displace, displace_hinges, time_warp, warp_at


def test_time_warp_by_hand():
    # τ = (0, ln 2, ln 0.5): increments 1, 2, 0.5 -> φ = 0, 1, 3, 3.5
    phi = time_warp([0.0, np.log(2.0), np.log(0.5)])
    assert phi == pytest.approx([0.0, 1.0, 3.0, 3.5])
    assert warp_at(phi, 1.5) == pytest.approx(2.0)  # halfway between φ_1 = 1 and φ_2 = 3


def test_time_warp_is_strictly_increasing_for_any_tau():
    rng = np.random.default_rng(0)
    for scale in (0.1, 3.0, 30.0, 1e6):
        phi = time_warp(rng.normal(scale=scale, size=2000))
        assert np.all(np.diff(phi) > 0)
    assert np.all(np.diff(time_warp([-1e9] * 5000)) > 0)  # clipped to ±TAU_LIMIT


def test_displacement_by_hand():
    root, rots = np.array([0.0, 0.0, 1.0]), Rotation.from_euler("z", [[0.0], [90.0]], degrees=True)
    d_rot = np.array([[0.0, 0.0, np.pi / 2], [0.0, 0.0, -np.pi / 2]])
    p, q = displace(root, rots, np.array([0.1, 0.0, -0.2]), d_rot)
    assert p == pytest.approx([0.1, 0.0, 0.8])
    # q1 exp(d1): 0° + 90° about z; q2 exp(d2): 90° − 90° = identity
    assert q.as_euler("zyx", degrees=True)[:, 0] == pytest.approx([90.0, 0.0], abs=1e-9)
    # local frame: about z after a 90° turn about x, the displacement turns about the new z
    q0 = Rotation.from_euler("x", 90, degrees=True)
    _, q1 = displace(root, Rotation.concatenate([q0]), np.zeros(3), [[0, 0, np.pi / 2]])
    assert np.allclose(q1.apply([1, 0, 0]), q0.apply([0, 1, 0]))
    assert displace_hinges([0.5, -0.2], [0.1, 0.1]) == pytest.approx([0.6, -0.1])


def test_knn_weights_by_hand():
    # two elites at distance² 0 and 0.0784 = σ² (σ = 0.28), fitness 0.5 and 1.0:
    # raw w = 0.5 e⁰ = 0.5 and 1.0 e⁻¹ = 0.3679 -> normalized 0.5761, 0.4239
    w = knn_weights([[0.0, 0.0], [0.28, 0.0]], [0.5, 1.0], np.zeros(2), np.ones(2), 0.28)
    assert w == pytest.approx([0.5 / (0.5 + np.exp(-1)), np.exp(-1) / (0.5 + np.exp(-1))])


def test_knn_proxy_interpolates_elite_traces():
    e = EliteSet(1, rule=EliteRule(radius=0.05))
    traces = {}
    for i, x in enumerate([0.0, 0.5, 1.0]):
        e.offer([x], 0.8, f"e{i}")
        traces[f"e{i}"] = np.full((4, 2), x)  # trace value = its parameter
    assert knn_proxy(EliteSet(1), traces.__getitem__, [0.3]) is None
    out = knn_proxy(e, traces.__getitem__, [0.5], k=3)
    assert out.shape == (4, 2) and out == pytest.approx(np.full((4, 2), 0.5))  # symmetric
    near_zero = knn_proxy(e, traces.__getitem__, [0.1], k=2)[0, 0]
    assert 0.0 < near_zero < 0.25  # pulled to the nearest elite


def test_parameterization_net_fits_a_smooth_mapping():
    import torch

    from paramimic.curriculum.parameterization_net import ParameterizationNet
    from paramimic.task_space import TaskSpace

    torch.set_num_threads(1)
    space = TaskSpace.from_ranges({"g": (0.5, 1.5), "h": (0.0, 1.0)})
    t = np.linspace(0, 1, 10)

    def truth(a):  # trace [10, 2]: a displacement and a τ that vary smoothly with a
        return np.stack([np.sin(np.pi * a[0] * t) * a[1], 0.3 * (a[0] - 1.0) * np.ones(10)], 1)

    rng = np.random.default_rng(0)
    params = space.sample(rng, 256)
    traces = np.stack([truth(a) for a in params])
    net = ParameterizationNet(space, (10, 2), hidden=(64, 64), lr=3e-3, seed=0)
    first = net.fit(params, traces, 1)
    last = net.fit(params, traces, 1500)
    assert net.version == 2 and last < 0.05 * first
    test = space.sample(rng, 32)
    err = net.predict(test) - np.stack([truth(a) for a in test])
    assert np.sqrt(np.mean(err**2)) < 0.05  # the traces' values are O(1)
