"""Push sequences of validation objects and the per-direction evidence weights."""

import math

import torch

from pushtoknow.training.calibration import direction_nll, push_sequences
from pushtoknow.training.data import load_push_tensors
from tiny_training import DATA_OBJECTS, DATA_PUSHES, tiny_dataset


def test_sequences_follow_each_objects_pushes_in_order(tmp_path_factory):
    pt = load_push_tensors(tiny_dataset(tmp_path_factory))
    seqs = push_sequences(pt, max_objects=DATA_OBJECTS)
    assert seqs.shape == (DATA_OBJECTS, DATA_PUSHES)
    for row in seqs:
        assert len(set(pt.object_index[row].tolist())) == 1  # one object per sequence
        assert pt.push_index[row].tolist() == sorted(pt.push_index[row].tolist())
    assert push_sequences(pt, max_objects=2).shape == (2, DATA_PUSHES)


def test_direction_nll_is_the_gaussian_nll_in_the_basis():
    mean = torch.zeros(1, 5)
    cov = torch.eye(5).expand(1, 5, 5) * 4.0
    nll = direction_nll(mean, cov, torch.zeros(1, 5))
    expected = 0.5 * (math.log(4.0) + math.log(2 * math.pi))  # zero error, variance 4
    torch.testing.assert_close(nll, torch.full((1, 5), expected))
    worse = direction_nll(mean, cov, torch.ones(1, 5))
    assert (worse > nll).all()
