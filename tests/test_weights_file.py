"""Weights files: plain meta round trip, and every bad file refused with one line, never run."""

import pickle

import numpy as np
import pytest
import torch
from weights_helpers import Evil, assert_refused

from suture_bt.weights_file import (
    WeightsError,
    WeightsNotFoundError,
    load_state,
    load_weights_file,
    plain,
    save_weights_file,
)

FMT = "suture_bt.test.v1"
HINT = "retrain it"


def _error(path) -> str:
    return assert_refused(lambda p: load_weights_file(p, FMT, HINT), path, None, HINT)


def test_round_trip_converts_numpy_meta_to_plain_types(tmp_path):
    net = torch.nn.Linear(3, 2)
    meta = {
        "pose": np.array([0.1, 0.2]),
        "n": np.int64(7),
        "x": np.float32(0.5),
        "pair": (1, 2),
        "nested": {"t": torch.ones(2), "s": "ok", "none": None},
    }
    path = tmp_path / "sub" / "w.pt"
    save_weights_file(path, FMT, {"net": net.state_dict()}, meta)
    state, back = load_weights_file(path, FMT, HINT)
    assert back["pose"] == [0.1, 0.2] and type(back["n"]) is int and back["n"] == 7
    assert type(back["x"]) is float and back["x"] == 0.5 and back["pair"] == [1, 2]
    assert torch.equal(back["nested"]["t"], torch.ones(2)) and back["nested"]["none"] is None
    other = torch.nn.Linear(3, 2)
    load_state(other, state["net"], path, HINT)
    assert torch.equal(other.weight, net.weight) and torch.equal(other.bias, net.bias)


def test_plain_refuses_objects_and_non_string_keys():
    with pytest.raises(TypeError, match=r"meta\['p'\]: PosixPath"):
        plain({"p": __import__("pathlib").Path("/x")})
    with pytest.raises(TypeError, match="key 1 is not a string"):
        plain({1: 2})
    with pytest.raises(TypeError, match="object"):
        save_weights_file("/nonexistent/never_written.pt", FMT, {}, {"o": object()})


def test_missing_file_is_a_file_not_found_weights_error(tmp_path):
    with pytest.raises(WeightsNotFoundError) as info:
        load_weights_file(tmp_path / "none.pt", FMT, HINT)
    assert isinstance(info.value, FileNotFoundError) and isinstance(info.value, ValueError)
    assert "none.pt: weights file not found; retrain it" in str(info.value)
    assert "not a file" in _error(tmp_path)


@pytest.mark.parametrize("how", ["torch", "pickle"])
def test_a_pickled_object_is_refused_and_never_executed(tmp_path, how):
    marker = tmp_path / "marker"
    path = tmp_path / "evil.pt"
    blob = {"format": FMT, "state": {}, "meta": {"x": Evil(marker)}}
    if how == "torch":
        torch.save(blob, path)
    else:
        path.write_bytes(pickle.dumps(blob))
    assert "refused" in _error(path) and "never code" in _error(path)
    assert not marker.exists()


def test_corrupted_text_empty_and_foreign_files_are_refused(tmp_path):
    good = tmp_path / "good.pt"
    save_weights_file(good, FMT, {"w": torch.zeros(1000)}, {})
    cut = tmp_path / "cut.pt"
    cut.write_bytes(good.read_bytes()[:2000])
    text = tmp_path / "text.pt"
    text.write_text("these are not weights\n")
    empty = tmp_path / "empty.pt"
    empty.touch()
    for path in (cut, text, empty):
        assert "not a readable weights file" in _error(path)
    other = tmp_path / "other.pt"
    save_weights_file(other, "suture_bt.other.v1", {}, {})
    assert "format 'suture_bt.other.v1'" in _error(other)
    untagged = tmp_path / "untagged.pt"
    torch.save({"state": {}, "meta": {}}, untagged)
    assert "format None" in _error(untagged)
    listed = tmp_path / "list.pt"
    torch.save([1, 2], listed)
    assert "format None" in _error(listed)
    nostate = tmp_path / "nostate.pt"
    torch.save({"format": FMT, "meta": {}}, nostate)
    assert "without a state or meta" in _error(nostate)


def test_load_state_reports_a_mismatch_in_one_line(tmp_path):
    state = torch.nn.Linear(3, 4).state_dict()
    for bad in (state, None, {"weight": torch.zeros(2, 3)}):
        with pytest.raises(WeightsError, match="weights do not match Linear") as info:
            load_state(torch.nn.Linear(3, 2), bad, tmp_path / "w.pt", HINT)
        assert "\n" not in str(info.value) and str(info.value).endswith(HINT)
