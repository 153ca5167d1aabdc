"""The filter math stands alone: no simulator, no MuJoCo."""

import subprocess
import sys


def test_filters_and_models_do_not_import_the_simulator():
    code = (
        "import sys, pushtoknow.filters, pushtoknow.models, pushtoknow.bench.filter;"
        "bad = [m for m in sys.modules if m.startswith(('mujoco', 'pushtoknow.testbed'))];"
        "assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
