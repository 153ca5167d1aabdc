"""Lower layers never import higher ones (README "Layout"): every `pushtoknow.X` import in a
module of package P, lazy imports inside functions included, must name a layer ≤ P's."""

import ast
from pathlib import Path

import pushtoknow

# rank of each subpackage / top-level module; equal ranks may import each other
RANKS = {
    "common": 0,
    "pretrained": 0,
    "geometry": 1,
    "testbed": 2,
    "datasets": 3,
    "filters": 3,
    "models": 4,
    "perception": 4.5,  # the footprint seen before a push and VisNet's measurement
    "active": 5,
    "baselines": 5,
    "training": 6,
    "identification": 6.5,  # simulator-in-the-loop fit: common … datasets, perception
    "inference": 7,
    "collection": 7.5,  # runs inference to collect training data, trains models
    "reporting": 7.8,  # units, tables, markdown, figures: renders results, imports no producer
    "evaluation": 8,
    "bench": 9,
    "viz": 9,
    "api": 9.5,  # the Python API re-exported by `import pushtoknow`
    "cli": 10,
}
ROOT = Path(pushtoknow.__file__).parent


def _layer(dotted: str) -> str | None:
    parts = dotted.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "pushtoknow" else None


def _imports(path: Path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.module


def test_every_layer_is_ranked():
    found = {p.stem if p.is_file() else p.name for p in ROOT.iterdir()}
    found = {f for f in found if not f.startswith("_") and f not in ("py",)}
    missing = {f for f in found if f not in RANKS and (ROOT / f).is_dir()}
    assert not missing, f"rank these packages in RANKS: {missing}"


def test_no_module_imports_a_higher_layer():
    bad = []
    for path in ROOT.rglob("*.py"):
        rel = path.relative_to(ROOT)
        own = rel.parts[0] if len(rel.parts) > 1 else rel.stem
        if own not in RANKS:
            continue
        for name in _imports(path):
            other = _layer(name)
            if other in RANKS and RANKS[other] > RANKS[own]:
                bad.append(f"{rel} imports {name}")
    assert not bad, "\n".join(bad)


# Sideways imports that the ranks allow but the design does not: running a model never needs
# the trainer (what both need from the camera lives in `perception`).
FORBIDDEN = {("inference", "training"), ("identification", "training")}


def test_forbidden_sideways_imports():
    bad = []
    for path in ROOT.rglob("*.py"):
        rel = path.relative_to(ROOT)
        own = rel.parts[0] if len(rel.parts) > 1 else rel.stem
        bad += [f"{rel} imports {n}" for n in _imports(path) if (own, _layer(n)) in FORBIDDEN]
    assert not bad, "\n".join(bad)
