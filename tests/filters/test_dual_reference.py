"""The dual update gives, for a seed, the posteriors it gave before its stages were separated
(`dual_reference.json`, written by the single-method update): the restructuring changed no
number. Float64 toys, every weighting × reassembly that stays regular over six steps."""

import json
from pathlib import Path

import pytest
import torch
from filter_toys import planar_toy, pushed_block

from pushtoknow.filters import DualFilter

REFERENCE = json.loads((Path(__file__).with_name("dual_reference.json")).read_text())
CASES = {
    "planar/marginal/updated": planar_toy,
    "planar/joint_samples/updated": planar_toy,
    "block/marginal/kept": pushed_block,
    "block/joint_samples/kept": pushed_block,
    "block/marginal/updated": pushed_block,
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_posteriors_match_the_reference(case):
    toy = CASES[case]()
    _, weighting, cross = case.split("/")
    _, obs = toy.simulate(4, 6, torch.Generator().manual_seed(3))
    filt = DualFilter(*toy.models(), toy.config(param_weighting=weighting, cross_covariance=cross))
    mean = toy.prior_mean.expand(4, -1).clone()
    cov = toy.prior_cov.expand(4, -1, -1).clone()
    gen = torch.Generator().manual_seed(7)
    for z in obs:
        mean, cov, info = filt(mean, cov, z, None, generator=gen)
    ref = REFERENCE[case]
    # The paper's literal reassembly ("kept") inflates the covariance by many orders of
    # magnitude over six steps and its weights degenerate (ESS → 1), so last-bit differences
    # between CPUs' BLAS kernels grow to ~1e-3 there (it matched on an AMD EPYC, not on an
    # Intel Xeon); the regular cases must match to round-off. A restructured stage that
    # computed anything else moves these numbers by far more.
    round_off = {"mean": (1e-9, 1e-12), "cov": (1e-9, 1e-14), "ess": (1e-9, 1e-9)}
    for name, value in (("mean", mean), ("cov", cov), ("ess", info.ess)):
        rtol, atol = (1e-2, 1e-2) if cross == "kept" else round_off[name]
        expected = torch.tensor(ref[name], dtype=value.dtype)
        torch.testing.assert_close(value, expected, rtol=rtol, atol=atol)
    assert info.stages.tolist() == ref["stages"]
