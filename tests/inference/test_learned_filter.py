"""The learned filter's own checks (`inference.learned_filter`)."""

import numpy as np

from pushtoknow.common.params import ObjectParams
from pushtoknow.identification.synthetic import simulate_pushes
from pushtoknow.inference.learned_filter import outside_training
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
