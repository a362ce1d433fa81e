"""Running normalisation statistics."""

import numpy as np
import torch

from dtd.agents.normalizer import RunningNormalizer


def test_matches_numpy_over_several_batches():
    rng = np.random.default_rng(0)
    data = rng.normal(loc=[1.0, -3.0, 10.0], scale=[0.5, 2.0, 4.0], size=(3000, 3))
    norm = RunningNormalizer(3, eps=1e-4, clip=100)
    for part in np.split(data, 3):
        norm.update(part)
    assert np.allclose(norm.mean.numpy(), data.mean(axis=0), atol=1e-5)
    assert np.allclose(norm.std.numpy(), data.std(axis=0), rtol=1e-5)
    normalized = norm.normalize(torch.as_tensor(data, dtype=torch.float32)).numpy()
    assert np.allclose(normalized.mean(axis=0), 0, atol=1e-4)
    assert np.allclose(normalized.std(axis=0), 1, atol=1e-4)


def test_clips_and_never_divides_by_less_than_eps():
    norm = RunningNormalizer(2, eps=0.01, clip=5.0)
    norm.update(np.zeros((10, 2)))  # no spread at all
    assert torch.all(norm.std == 0.01)
    out = norm.normalize(torch.tensor([[1.0, -1.0]]))
    assert out.tolist() == [[5.0, -5.0]]


def test_accepts_any_leading_shape_and_round_trips():
    norm = RunningNormalizer(2)
    norm.update(np.arange(24, dtype=np.float64).reshape(3, 4, 2))
    assert norm.count == 12
    restored = RunningNormalizer(2)
    restored.load_state_dict(norm.state_dict())
    assert torch.equal(restored.mean, norm.mean) and torch.equal(restored.std, norm.std)
