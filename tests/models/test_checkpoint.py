"""Checkpoints: save → load round trip, and clear errors for files that cannot be loaded."""

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from tiny_models import CAMERA, prior, square_context, tiny_config

from pushtoknow.common.errors import CheckpointError, PushToKnowError
from pushtoknow.filters.base import FilterConfig
from pushtoknow.models.checkpoint import (
    CHECKPOINT_FILE,
    CHECKPOINT_VERSION,
    InferenceSettings,
    ParamPrior,
    load_checkpoint,
    new_model,
    save_checkpoint,
)
from pushtoknow.models.networks import VisNet, VisNetConfig
from pushtoknow.pretrained import resolve_model_path

VARIANTS = ["vt-addf", "vt-jdf", "v-ddf"]
SIGMA_POINTS = 30
VISNET = VisNetConfig(
    in_channels=5,
    image_size=CAMERA.width,
    channels=(2, 2),
    kernel_sizes=(3, 3),
    strides=(2, 2),
    hidden_dims=(4, 4),
)


def make_model(variant="vt-addf", seed=0):
    torch.manual_seed(seed)
    k = 5
    a = torch.randn(k, k) * 0.3
    model = new_model(
        variant,
        tiny_config(),
        FilterConfig(),
        VisNet(VISNET),
        ParamPrior(torch.linspace(-0.5, 0.5, k), a @ a.T + 0.1 * torch.eye(k)),
        CAMERA,
        info={"seed": seed, "data": "somewhere", "nested": {"a": [1, 2.5], "b": None}},
    )
    model.inference = InferenceSettings(update_every=5, noise_scale=4.0, num_sigma_points=40)
    return model.eval()


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """(model, run directory) of a saved vt-addf model."""
    model = make_model()
    run = tmp_path_factory.mktemp("ckpt") / "run"
    path = save_checkpoint(model, run)
    assert path == run / CHECKPOINT_FILE
    return model, run


def payload_of(run):
    return torch.load(run / CHECKPOINT_FILE, map_location="cpu", weights_only=True)


def write_payload(payload, tmp_path):
    path = tmp_path / "edited.pt"
    torch.save(payload, path)
    return path


def one_step(model, seed=0):
    """Predict + update of the model's filter on fixed inputs and noise."""
    filt = model.build_filter(SIGMA_POINTS, noise_scale=1.0)
    filt.eval()
    ctx = square_context(2)
    mean, cov = prior(2)
    mean = mean + torch.tensor([0.002, -0.001, 0.05, 0.1, -0.2, 0.05, 0.0, 0.1])
    with torch.no_grad():
        z = filt.observation(mean.unsqueeze(1), ctx).squeeze(1) + 0.01
        noise = filt.draw_noise(2, torch.Generator().manual_seed(seed))
        return filt(mean, cov, z, ctx, noise)[:2]


def visnet_out(model):
    gen = torch.Generator().manual_seed(1)
    rgbd = torch.rand(3, 4, CAMERA.height, CAMERA.width, generator=gen)
    mask0 = (torch.rand(3, 1, CAMERA.height, CAMERA.width, generator=gen) > 0.5).float()
    with torch.no_grad():
        return model.visnet(rgbd, mask0)


@pytest.mark.parametrize("variant", VARIANTS)
def test_round_trip_is_bit_identical(variant, tmp_path):
    model = make_model(variant, seed=VARIANTS.index(variant))
    save_checkpoint(model, tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == [CHECKPOINT_FILE]  # no temp file left
    loaded = load_checkpoint(tmp_path)

    assert loaded.variant == variant and loaded.vision_only == (variant == "v-ddf")
    assert loaded.models_config == model.models_config
    assert loaded.filter_config == model.filter_config
    assert loaded.visnet.config == model.visnet.config
    assert loaded.camera == model.camera
    assert loaded.inference == model.inference
    assert loaded.info == model.info
    assert torch.equal(loaded.prior.mean, model.prior.mean)
    assert torch.equal(loaded.prior.cov, model.prior.cov)

    before = model.models.modules().state_dict()
    after = loaded.models.modules().state_dict()
    assert before.keys() == after.keys()
    assert all(torch.equal(before[k], after[k]) for k in before)
    nets = [loaded.visnet, *loaded.models.modules()]
    assert not any(m.training for net in nets for m in net.modules())  # loaded in eval mode

    for a, b in zip(one_step(model), one_step(loaded), strict=True):
        assert torch.isfinite(a).all()
        assert torch.equal(a, b)
    assert torch.equal(visnet_out(model), visnet_out(loaded))


def test_build_filter_defaults_to_the_calibrated_settings(saved):
    model, run = saved
    loaded = load_checkpoint(run / CHECKPOINT_FILE)  # the file itself also works
    filt = loaded.build_filter()
    assert filt.config.num_sigma_points == 40
    assert filt.observation_noise.scale == 4.0
    assert loaded.build_filter(12, noise_scale=2.0).observation_noise.scale == 2.0


def test_missing_checkpoint(tmp_path):
    with pytest.raises(CheckpointError, match="no checkpoint at"):
        load_checkpoint(tmp_path / "nonexistent")
    with pytest.raises(CheckpointError, match=f"no checkpoint at .*{CHECKPOINT_FILE}"):
        load_checkpoint(tmp_path)  # a directory without model.pt


def test_random_bytes_are_not_a_checkpoint(tmp_path):
    path = tmp_path / "model.pt"
    path.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(CheckpointError, match="not a readable pushtoknow checkpoint") as e:
        load_checkpoint(path)
    assert str(path) in str(e.value)
    assert isinstance(e.value, PushToKnowError)


def test_other_torch_files_are_not_a_checkpoint(tmp_path):
    for i, obj in enumerate([[1, 2, 3], {"format": "something-else"}, {"w": torch.zeros(2)}]):
        path = tmp_path / f"f{i}.pt"
        torch.save(obj, path)
        with pytest.raises(CheckpointError, match="is not a pushtoknow checkpoint"):
            load_checkpoint(path)


def test_other_format_version(saved, tmp_path):
    _, run = saved
    payload = payload_of(run)
    payload["format_version"] = CHECKPOINT_VERSION + 1
    payload["pushtoknow_version"] = "9.9.9"
    with pytest.raises(CheckpointError) as e:
        load_checkpoint(write_payload(payload, tmp_path))
    msg = str(e.value)
    assert f"format version {CHECKPOINT_VERSION + 1}" in msg
    assert f"reads version {CHECKPOINT_VERSION}" in msg and "9.9.9" in msg


def test_models_config_that_does_not_match_the_weights(saved, tmp_path):
    _, run = saved
    payload = payload_of(run)
    payload["models_config"]["process"]["hidden_dims"] = [7, 7]
    with pytest.raises(CheckpointError, match="weights of the filter networks do not match") as e:
        load_checkpoint(write_payload(payload, tmp_path))
    assert "process" in str(e.value)  # names a mismatching tensor


def test_visnet_config_that_does_not_match_the_weights(saved, tmp_path):
    _, run = saved
    payload = payload_of(run)
    payload["visnet_config"]["hidden_dims"] = [5, 4]
    with pytest.raises(CheckpointError, match="weights of the VisNet do not match"):
        load_checkpoint(write_payload(payload, tmp_path))


def test_invalid_or_missing_config(saved, tmp_path):
    _, run = saved
    payload = payload_of(run)
    payload["models_config"]["process"]["input_dim"] = 99  # fails the config's own validation
    with pytest.raises(CheckpointError, match="config does not fit"):
        load_checkpoint(write_payload(payload, tmp_path))
    payload = payload_of(run)
    del payload["camera"]
    with pytest.raises(CheckpointError, match="config does not fit.*camera"):
        load_checkpoint(write_payload(payload, tmp_path))


def test_unknown_variant(saved, tmp_path):
    _, run = saved
    payload = payload_of(run)
    payload["variant"] = "bogus"
    with pytest.raises(CheckpointError, match="unknown variant 'bogus'.*vt-addf"):
        load_checkpoint(write_payload(payload, tmp_path))
    with pytest.raises(CheckpointError, match="unknown variant"):
        make_model("bogus")


def test_resolve_model_path(tmp_path):
    assert resolve_model_path(str(tmp_path)) == tmp_path
    with pytest.raises(CheckpointError, match="no shipped model 'bogus'"):
        resolve_model_path("pretrained:bogus")


def test_sim_config_of_models_saved_before_the_orientation_marker():
    from pushtoknow.testbed.sim_config import SimConfig, stored_sim_config

    assert stored_sim_config(None).orientation_marker is False
    old = SimConfig().model_dump(mode="json")
    del old["orientation_marker"]
    assert stored_sim_config(old).orientation_marker is False
    assert stored_sim_config(SimConfig().model_dump_json()).orientation_marker is True


def test_models_saved_before_testbed_versions_read_back_as_version_1(saved, tmp_path):
    from pushtoknow.testbed.sim_config import TESTBED_VERSION, SimConfig

    _, run = saved
    payload = payload_of(run)
    old = SimConfig().model_dump(mode="json")  # as version 1 wrote it: no newer fields
    del old["testbed_version"], old["physics"]["solver"], old["pad"]["contact_timeconst"]
    payload["info"]["sim_config"] = old
    model = load_checkpoint(write_payload(payload, tmp_path))
    assert model.sim_config.testbed_version == 1  # so a simulator refuses it
    assert model.sim_config.physics.solver == "Newton"  # version 1's, filled in
    assert model.sim_config.pad.contact_timeconst == 0.02
    payload["info"]["sim_config"] = SimConfig().model_dump(mode="json")
    (tmp_path / "new").mkdir()
    model = load_checkpoint(write_payload(payload, tmp_path / "new"))
    assert model.sim_config.testbed_version == TESTBED_VERSION


@given(
    mean=st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3),
    std=st.lists(st.floats(0.1, 1.5), min_size=3, max_size=3),
    rho=st.floats(-0.8, 0.8),
    level=st.sampled_from([0.68, 0.9, 0.95]),
)
@settings(max_examples=40, deadline=None)
def test_a_prior_covering_the_range_reaches_both_ends_and_keeps_correlations(mean, std, rho, level):
    from pushtoknow.models.checkpoint import RANGE_MARGIN

    s = torch.tensor(std, dtype=torch.float64)
    corr = torch.eye(3, dtype=torch.float64)
    corr[0, 1] = corr[1, 0] = rho
    p = ParamPrior(torch.tensor(mean), (corr * s[:, None] * s[None, :]).float())
    wide = p.covering_range(level)
    z = torch.distributions.Normal(0.0, 1.0).icdf(torch.tensor(0.5 + 0.5 * level)).item()
    w = wide.cov.double().diagonal().sqrt()
    m = wide.mean.double()
    assert torch.equal(wide.mean, p.mean)
    assert (m - z * w <= -1 - RANGE_MARGIN + 1e-5).all()
    assert (m + z * w >= 1 + RANGE_MARGIN - 1e-5).all()
    assert (w >= s - 1e-6).all()  # never narrower
    wide_corr = wide.cov.double() / (w[:, None] * w[None, :])
    assert torch.allclose(wide_corr, corr, atol=1e-5)
    already = s * z >= 1 + RANGE_MARGIN + torch.tensor(mean, dtype=torch.float64).abs()
    assert torch.allclose(w[already], s[already], rtol=1e-6)


def test_prior_coverage_level_is_checked():
    p = ParamPrior(torch.zeros(2), torch.eye(2))
    with pytest.raises(ValueError, match="prior coverage level"):
        p.covering_range(1.0)


def test_damaged_weights_are_refused_naming_the_file(saved, tmp_path):
    """A checkpoint stores a SHA-256 of its weights: bytes changed inside a weight tensor
    (a damaged file) or a non-finite weight give a CheckpointError naming the file, never a
    model that predicts from garbage."""
    from pushtoknow.models.checkpoint import weights_digest

    _, run = saved
    payload = torch.load(run / CHECKPOINT_FILE, weights_only=True)
    assert payload["weights_sha256"] == weights_digest(
        payload["models_state"], payload["visnet_state"]
    )
    name = next(k for k, t in payload["visnet_state"].items() if t.is_floating_point())
    damaged = dict(payload, visnet_state=dict(payload["visnet_state"]))
    damaged["visnet_state"][name] = damaged["visnet_state"][name] + 1e-3
    torch.save(damaged, tmp_path / "damaged.pt")
    with pytest.raises(CheckpointError, match=r"damaged\.pt: the weights do not match"):
        load_checkpoint(tmp_path / "damaged.pt")
    # an old checkpoint without a digest still gets the finiteness check
    nan = {k: v for k, v in damaged.items() if k != "weights_sha256"}
    nan["visnet_state"][name] = torch.full_like(nan["visnet_state"][name], float("nan"))
    torch.save(nan, tmp_path / "nan.pt")
    with pytest.raises(CheckpointError, match=f"weight {name} holds NaN"):
        load_checkpoint(tmp_path / "nan.pt")
