"""Shared test helpers (import as `from tests.helpers import ...` is avoided; pytest rootdir
puts this folder on sys.path via conftest)."""

import numpy as np
from matplotlib.path import Path as MplPath

from pushtoknow.common.camera import CameraModel


def rasterise_footprint(
    vertices_obj: np.ndarray, pose, camera: CameraModel, z: float = 0.0
) -> np.ndarray:
    """(H, W) bool: pixels whose centre lies inside the footprint placed at pose (x, y, θ) on
    the plane at height z."""
    x, y, th = pose
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    world = vertices_obj @ R.T + np.array([x, y])
    uv = camera.world_to_pixel(world, z)
    uu, vv = np.meshgrid(np.arange(camera.width), np.arange(camera.height))
    inside = MplPath(uv).contains_points(np.column_stack([uu.ravel(), vv.ravel()]))
    return inside.reshape(camera.height, camera.width)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


BELIEF_FIELDS = ("mean_norm", "cov_norm")  # what a recorded run keeps of each estimate


def recorded_run(estimator: str, policy: str):
    """The shipped model's `estimator` on held-out catalogue:117 (2 pushes, constant and
    release, 4 candidates, seed 0) under `policy`: `(InferenceConfig, InferenceResult)`."""
    from pushtoknow.inference import InferenceConfig, infer_simulated
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.pretrained import resolve_model_path
    from pushtoknow.testbed.object_refs import load_object_spec

    model = load_checkpoint(resolve_model_path("pretrained"))
    cfg = InferenceConfig(
        estimator=estimator, pushes=2, policy=policy, candidates=4, profiles=("constant", "release")
    )
    return cfg, infer_simulated(model, load_object_spec("catalogue:117"), cfg, seed=0)


def record_run(estimator: str, recording: str, policies: tuple[str, ...]) -> None:
    """Write `recorded_run`'s pushes and normalised beliefs under each of `policies` to
    tests/inference/data/`recording` (after a change meant to change the estimates:
    `python tests/helpers.py physics physics_filter_catalogue117_seed0.json uniform`)."""
    import json
    from pathlib import Path

    out = {}
    for policy in policies:
        _, res = recorded_run(estimator, policy)
        out[policy] = {
            "pushes": [e.push.as_array().tolist() for e in res.estimates],
            **{n: [getattr(e, n).tolist() for e in res.estimates] for n in BELIEF_FIELDS},
        }
    (Path(__file__).parent / "inference" / "data" / recording).write_text(json.dumps(out))


def assert_recorded_run(
    estimator: str,
    recording: str,
    rtol: float,
    atol: float,
    correlation_atol: float | None = None,
) -> list:
    """Run `recorded_run` under each policy of tests/inference/data/`recording`; assert its
    pushes equal the recorded ones and its normalised beliefs equal them within (rtol, atol);
    with `correlation_atol`, each covariance as its standard deviations (within rtol, atol)
    and correlations (within correlation_atol) instead of entry by entry. Returns each
    policy's `(InferenceConfig, InferenceResult)`."""
    import json
    from pathlib import Path

    data = Path(__file__).parent / "inference" / "data" / recording
    runs = []
    for policy, want in json.loads(data.read_text()).items():
        cfg, res = recorded_run(estimator, policy)
        assert [e.push.as_array().tolist() for e in res.estimates] == want["pushes"]
        for name in BELIEF_FIELDS:
            got = np.array([getattr(e, name) for e in res.estimates])
            if name == "cov_norm" and correlation_atol is not None:
                for k, (g, w) in enumerate(zip(got, np.asarray(want[name]), strict=True)):
                    s_g, s_w = np.sqrt(np.diagonal(g)), np.sqrt(np.diagonal(w))
                    np.testing.assert_allclose(s_g, s_w, rtol=rtol, atol=atol, err_msg=f"std {k}")
                    np.testing.assert_allclose(
                        g / np.outer(s_g, s_g), w / np.outer(s_w, s_w), atol=correlation_atol,
                        err_msg=f"correlation {k}",
                    )  # fmt: skip
                continue
            np.testing.assert_allclose(got, want[name], rtol=rtol, atol=atol, err_msg=name)
        runs.append((cfg, res))
    return runs


if __name__ == "__main__":
    import sys

    record_run(sys.argv[1], sys.argv[2], tuple(sys.argv[3:]))
