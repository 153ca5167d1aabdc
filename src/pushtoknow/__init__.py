"""pushtoknow: learn an object's mass, friction, centre of mass and inertia by pushing it.

The layers, and which may import which, are stated in docs/DESIGN.md §1 (checked by
tests/test_layers.py and tests/test_import_cycles.py).
"""

__version__ = "0.1.0"
