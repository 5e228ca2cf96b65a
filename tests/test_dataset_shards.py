"""Dataset shards: joined in name order, plain arrays only, a clear error when none exist."""

import numpy as np
import pytest

from suture_bt.dataset_shards import load_shards


def test_shards_join_in_name_order(tmp_path):
    np.savez(tmp_path / "shard_001.npz", x=np.array([3, 4]), y=np.zeros((2, 2)))
    np.savez(tmp_path / "shard_000.npz", x=np.array([1, 2]), y=np.ones((2, 2)))
    np.savez(tmp_path / "other_000.npz", x=np.array([9]), y=np.ones((1, 2)))
    d = load_shards(tmp_path, "shard_*.npz", "make it")
    assert d["x"].tolist() == [1, 2, 3, 4] and d["y"].shape == (4, 2)


def test_missing_shards_name_the_command(tmp_path):
    with pytest.raises(FileNotFoundError, match="suture-bt data needle"):
        load_shards(tmp_path, "shard_*.npz", "suture-bt data needle")


def test_object_arrays_are_refused(tmp_path):
    np.savez(tmp_path / "shard_000.npz", x=np.array([{"code": 1}], dtype=object))
    with pytest.raises(ValueError, match="pickle"):
        load_shards(tmp_path, "shard_*.npz", "make it")
