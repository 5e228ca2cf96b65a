"""Target registries of the ``NAME TARGET`` subcommands (data, train)."""

import argparse

import pytest

from suture_bt.commands import data, train
from suture_bt.commands.targets import add_target_command, target_registry


def test_registry_decorator_registers_once_and_returns_the_function():
    targets, target = target_registry()

    def f(args):
        return {"ran": args.target}

    assert target("a")(f) is f and targets == {"a": f}
    with pytest.raises(ValueError, match="'a' is registered twice"):
        target("a")(f)


def test_target_command_parses_known_targets_and_calls_run():
    targets, target = target_registry()
    target("b")(print)
    target("a")(print)
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    p = add_target_command(sub, "do", "do a thing", targets, "which thing", lambda a: 7)
    p.add_argument("--n", type=int)
    args = parser.parse_args(["do", "a", "--n", "3"])
    assert args.target == "a" and args.n == 3 and args.func(args) == 7
    assert "{a,b}" in p.format_usage()  # choices sorted
    with pytest.raises(SystemExit):
        parser.parse_args(["do", "c"])


def test_data_and_train_register_their_targets():
    # ``train needle`` trains on either needle dataset.
    assert sorted(data.TARGETS) == ["calibration", "needle", "needle-varied"]
    assert sorted(train.TARGETS) == ["calibration", "needle"]
    assert (
        data.TARGETS["needle"] is data._needle
        and data.TARGETS["needle-varied"] is data._needle_varied
        and train.TARGETS["calibration"] is train._calibration
    )
