"""pushtoknow: learn an object's mass, friction, centre of mass and inertia by pushing it.

Layers (lower never imports higher):
common → testbed → geometry → filters → models → active → training → inference → evaluation,
plus baselines, datasets, bench and cli. `filters` holds the filter math and the abstract model
interfaces (torchfilter style); `models` implements them with networks + geometry. Neither
imports MuJoCo or the testbed.
"""

__version__ = "0.1.0"
