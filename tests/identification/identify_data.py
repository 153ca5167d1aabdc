"""A tiny rendered dataset for the identification tests (not a test module)."""

import numpy as np

from pushtoknow.common.params import ObjectParams
from pushtoknow.datasets.shards import ObjectEpisode, shard_path, write_shard
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim import PushSimulator
from pushtoknow.testbed.sim_config import SimConfig

SHORT = SimConfig().model_copy(
    update={"push": SimConfig().push.model_copy(update={"horizon": 2.0})}
)
SPEC = ObjectSpec("rect1", ObjectParams(0.5, 0.5, 0.01, 0.0, 1.0e-3), name="tiny")


def write_tiny_dataset(out, profiles=("constant",)):
    """One rect1 object, one push per profile, rendered (2 s pushes)."""
    out.mkdir(parents=True, exist_ok=True)
    sim = PushSimulator(SPEC, SHORT)
    rng = np.random.default_rng(0)
    records = []
    for profile in profiles:
        sim.reset((0.01, -0.01, 0.3))
        x0 = float(SPEC.footprint.polygon.bounds[0])
        c, s = np.cos(0.3), np.sin(0.3)
        cp = (0.01 + c * x0, -0.01 + s * x0)
        speed = 0.02 if profile == "constant" else 0.4
        records.append(sim.execute(Push(cp, 0.3, profile, speed), rng))
    sim.close()
    write_shard(
        shard_path(out, 0),
        [ObjectEpisode(SPEC, 0, records)],
        fingerprint="test",
        shard_index=0,
        sim_config_json=SHORT.model_dump_json(),
    )
    return out
