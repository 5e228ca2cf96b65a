"""Training reads dataset shards, trains a few seeded steps and writes loadable weights."""

import numpy as np
import pytest

from suture_bt.perception.network import load_network
from suture_bt.perception.training import TrainConfig, heatmap_targets, load_dataset, train


def _write_dataset(folder, n=8, seed=0):
    rng = np.random.default_rng(seed)
    images = np.full((n, 64, 96, 3), (215, 140, 132), np.uint8)
    masks = np.zeros((n, 64, 96), np.uint8)
    kps = np.zeros((n, 2, 2), np.float32)
    for i in range(n):
        y = int(rng.integers(10, 54))
        images[i, y : y + 2, 20:70] = 150
        masks[i, y : y + 2, 20:70] = 255
        kps[i] = ((20, y + 0.5), (69, y + 0.5))
    np.savez(
        folder / "shard_0000.npz",
        images=images,
        masks=masks,
        keypoints=kps,
        visible=np.ones((n, 2), bool),
        pose_cam=np.tile(np.eye(4), (n, 1, 1)),
        scenario=np.zeros(n, int),
    )


def test_heatmap_targets_peak_at_keypoints_and_zero_when_hidden():
    h = heatmap_targets(np.array([[5.0, 7.0], [20.0, 3.0]]), np.array([True, False]), 16, 32)
    assert np.unravel_index(h[0].argmax(), h[0].shape) == (7, 5)
    assert h[0].max() == pytest.approx(1.0) and h[1].max() == 0.0


def test_train_few_steps_writes_loadable_weights(tmp_path):
    _write_dataset(tmp_path)
    assert load_dataset(tmp_path)["images"].shape == (8, 64, 96, 3)
    out = tmp_path / "w.pt"
    cfg = TrainConfig(steps=3, batch=2, crop=(64, 48), width=8, val_every=3, threads=1)
    result = train(tmp_path, out, cfg, progress=False)
    assert result["steps"] == 3 and 0.0 <= result["final"]["mask_iou"] <= 1.0
    assert load_network(out).width == 8


def test_several_dataset_folders_are_joined_in_order(tmp_path):
    a, b = tmp_path / "default", tmp_path / "varied"
    a.mkdir()
    b.mkdir()
    _write_dataset(a, n=8, seed=0)
    _write_dataset(b, n=6, seed=1)
    joined = load_dataset([a, b])
    assert joined["images"].shape == (14, 64, 96, 3)
    assert np.array_equal(joined["keypoints"][8:], load_dataset(b)["keypoints"])


def test_train_command_takes_several_folders(tmp_path, capsys):
    from suture_bt.cli import main

    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    _write_dataset(a)
    _write_dataset(b, seed=1)
    out = tmp_path / "two.pt"
    args = ["train", "needle", "--data", str(a), str(b), "--out", str(out), "--steps", "2"]
    assert main(args) == 0
    assert '"train_images": ' in capsys.readouterr().out and out.is_file()


def test_missing_dataset_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="suture-bt data needle"):
        load_dataset(tmp_path)


def test_train_command_writes_weights(tmp_path, capsys):
    from suture_bt.cli import main

    _write_dataset(tmp_path)
    out = tmp_path / "cli.pt"
    args = ["train", "needle", "--data", str(tmp_path), "--out", str(out), "--steps", "2"]
    assert main(args) == 0
    assert out.is_file() and '"steps": 2' in capsys.readouterr().out
