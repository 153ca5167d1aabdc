"""pushtoknow: learn an object's mass, friction, centre of mass and inertia by pushing it.

Layers (lower never imports higher):
common → testbed → geometry → models → filters → active → training → evaluation,
plus baselines, datasets, bench and cli.
"""

__version__ = "0.1.0"
