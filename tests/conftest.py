import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import torch

# pytest-xdist runs one worker per core: one torch thread each avoids oversubscription
torch.set_num_threads(1)

sys.path.insert(0, str(Path(__file__).parent))
