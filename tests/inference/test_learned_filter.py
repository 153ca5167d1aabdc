"""The learned filter's own checks (`inference.learned_filter`)."""

import numpy as np

from pushtoknow.common.params import ObjectParams
from pushtoknow.identification.synthetic import simulate_pushes
from pushtoknow.inference.learned_filter import outside_training, training_footprint_bounds
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.shapes import footprint_from_shape
from pushtoknow.testbed.sim_config import SimConfig

SIM = SimConfig(render=False)


def _pushes(mass: float, friction: float, shape="rect1", inertia=1.0e-3):
    spec = ObjectSpec(shape, ObjectParams(mass, friction, 0.0, 0.0, inertia))
    return spec, simulate_pushes(spec, ["constant"], seed=2, config=SIM, centred=True)


def test_an_object_like_the_training_ones_is_not_flagged():
    spec, records = _pushes(0.6, 0.5)
    assert outside_training(records, spec.footprint, SIM) == ()


def test_a_heavy_object_and_a_large_outline_are_flagged_without_the_truth():
    """μ·m = 2.4 kg (training: at most 0.84 kg) is read off the steady push force; a 30 × 24 cm
    plate is larger than every training shape; neither needs the object's truth."""
    spec, records = _pushes(4.0, 0.6, inertia=4.0e-3)
    reasons = outside_training(records, spec.footprint, SIM)
    assert len(reasons) == 1 and reasons[0].startswith("μ·m ≈ 2.")
    plate = footprint_from_shape({"type": "rectangle", "width": 0.30, "height": 0.24})
    both = outside_training(records, plate, SIM)
    assert len(both) == 3 and "largest radius 19.2 cm" in both[1] and "area 720 cm²" in both[2]
    light = [r.tracks_only() for r in records]
    for r in light:
        r.tactile[:, :2] *= 0.005  # 200 times weaker: μ·m ≈ 0.012 kg, below half the least
    assert "outside the 0.035–0.84 kg" in outside_training(light, spec.footprint, SIM)[0]
    assert np.isfinite(records[0].tactile).all()


def test_the_footprint_range_is_the_training_objects():
    """A model trained on random shapes too (5–25 cm) knows smaller and larger outlines than the
    catalogue's; its range is regenerated from the checkpoint's provenance, and a checkpoint
    without provenance (or with one that cannot be regenerated) falls back to the catalogue."""
    catalogue = training_footprint_bounds(None)
    assert training_footprint_bounds({"objects_from": "no-such-source", "objects": 4}) == catalogue
    trained = training_footprint_bounds(
        {"objects_from": "catalogue-train", "objects": 600, "data_seed": 3}
    )
    np.testing.assert_allclose(trained, catalogue, rtol=1e-9)
    info = {"objects_from": "catalogue-train+random", "objects": 40, "data_seed": 3}
    (r_lo, r_hi), (a_lo, a_hi) = training_footprint_bounds(info)
    assert r_lo < catalogue[0][0] and r_hi > catalogue[0][1] and a_lo < catalogue[1][0]
    spec, records = _pushes(0.6, 0.5)
    bar = footprint_from_shape({"type": "rectangle", "width": 0.28, "height": 0.05})
    assert any("largest radius 14.2 cm" in r for r in outside_training(records, bar, SIM))
    assert not any("radius" in r for r in outside_training(records, bar, SIM, info))
    small = footprint_from_shape({"type": "rectangle", "width": 0.05, "height": 0.05})
    assert any("area 25 cm²" in r for r in outside_training(records, small, SIM))
    assert not any("area" in r for r in outside_training(records, small, SIM, info))
