"""The needle CNN: size, output shape, sub-pixel keypoint decoding, weights I/O and errors."""

import numpy as np
import pytest
import torch

from suture_bt.perception.network import (
    DEFAULT_WEIGHTS,
    INPUT_SIZE,
    FrozenByShape,
    NeedleNet,
    WeightsError,
    count_parameters,
    decode_ends,
    decode_keypoints,
    for_inference,
    frozen_for_inference,
    load_network,
    save_weights,
    to_input,
)


def test_network_is_small_and_outputs_three_half_resolution_maps():
    net = NeedleNet().eval()
    assert 50_000 < count_parameters(net) < 500_000
    w, h = INPUT_SIZE
    with torch.inference_mode():
        out = net(to_input(np.zeros((h, w, 3), np.uint8)))
    assert out.shape == (1, 3, h // 2, w // 2)


def test_decode_keypoints_is_sub_pixel():
    h, w = 40, 60
    yy, xx = np.mgrid[0:h, 0:w]
    u, v = 23.3, 17.6
    g = np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * 1.5**2))
    logits = torch.logit(torch.tensor(g * 0.98 + 0.01, dtype=torch.float32))[None, None]
    kp, score = decode_keypoints(logits)
    assert np.linalg.norm(kp[0, 0] - (u, v)) < 0.15
    assert score[0, 0] > 0.9


def test_weights_round_trip(tmp_path):
    torch.manual_seed(0)
    net = NeedleNet(width=8)
    path = tmp_path / "w.pt"
    save_weights(net, path, {"note": "test"})
    back = load_network(path)
    x = torch.rand(1, 3, 64, 96)
    net.eval()
    with torch.inference_mode():
        assert torch.allclose(net(x), back(x))


def test_missing_weights_error_names_the_file(tmp_path):
    missing = tmp_path / "nope.pt"
    with pytest.raises(WeightsError, match="nope.pt"):
        load_network(missing)


def test_mismatched_weights_error(tmp_path):
    path = tmp_path / "bad.pt"
    torch.save({"format": "something else"}, path)
    with pytest.raises(WeightsError, match="bad.pt"):
        load_network(path)
    blob = {"format": "suture_bt.needle_net.v2", "width": 16, "state_dict": {"x": torch.zeros(1)}}
    torch.save(blob, path)
    with pytest.raises(WeightsError, match="do not match"):
        load_network(path)


def test_shipped_weights_load_and_run_on_a_rendered_frame():
    if not DEFAULT_WEIGHTS.is_file():
        pytest.fail(f"shipped weights missing: {DEFAULT_WEIGHTS}")
    from suture_bt.sim.camera import render_view, stereo_model
    from suture_bt.sim.world import World

    net = load_network()
    with World.from_scene() as world:
        cam = stereo_model(640, 360).left
        rgb = render_view(world.client, cam, with_segmentation=False).rgb
    x = to_input(rgb[:352])
    with torch.inference_mode():
        out = net(x)
    assert out.shape == (1, 3, 176, 320) and torch.isfinite(out).all()


def test_decode_ends_finds_both_peaks_and_orders_base_first():
    h, w = 40, 60
    yy, xx = np.mgrid[0:h, 0:w]

    def gauss(u, v):
        return np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * 1.5**2))

    def logit(p):
        return torch.logit(torch.tensor(p * 0.98 + 0.01, dtype=torch.float32))[None]

    ends = np.maximum(gauss(10.2, 12.0), 0.9 * gauss(45.0, 30.4))
    ends_kp, scores = decode_ends(logit(ends), logit(gauss(45.0, 30.4)))
    np.testing.assert_allclose(ends_kp[0], [[45.0, 30.4], [10.2, 12.0]], atol=0.15)
    assert scores.shape == (1, 2)


def test_inference_copy_gives_the_same_outputs_and_leaves_the_original_alone():
    torch.manual_seed(3)
    net = NeedleNet(width=8)
    net.train()
    x = torch.rand(2, 3, 64, 96)
    net(x)  # moves the BatchNorm running statistics off their defaults
    net.eval()
    fast = for_inference(net)
    with torch.no_grad():
        ref = net(x)
        out = fast(x.contiguous(memory_format=torch.channels_last))
    assert torch.allclose(ref, out, atol=1e-4)
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in fast.modules())
    assert any(isinstance(m, torch.nn.BatchNorm2d) for m in net.modules())


def test_frozen_graphs_give_the_modules_bits_at_each_shape():
    """Each input shape gets its own frozen graph, with the inference copy's exact outputs;
    with autograd on, the module itself runs."""
    torch.manual_seed(4)
    net = NeedleNet(width=8).eval()
    frozen = frozen_for_inference(net)
    for shape in ((1, 3, 64, 96), (1, 3, 32, 48), (1, 3, 64, 96)):
        x = torch.rand(shape).contiguous(memory_format=torch.channels_last)
        with torch.inference_mode():
            assert torch.equal(frozen(x), frozen.module(x))
    assert len(frozen._graphs) == 2
    assert all(g is not frozen.module for g in frozen._graphs.values())
    x = torch.rand(1, 3, 32, 48, requires_grad=True)
    assert frozen(x).requires_grad  # the module, with autograd


def test_a_module_that_cannot_be_traced_runs_as_itself():
    class Counts(torch.nn.Module):
        def forward(self, x):
            return int(x.shape[0])  # not a tensor: no graph can be traced

    frozen = FrozenByShape(Counts().eval())
    with torch.no_grad():
        assert frozen(torch.ones(3, 2)) == 3
    assert all(g is frozen.module for g in frozen._graphs.values())
