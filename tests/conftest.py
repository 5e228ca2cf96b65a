"""Shared fixtures: fixed seeds and a clean py_trees Blackboard for every test."""

import numpy as np
import py_trees
import pytest


@pytest.fixture(autouse=True)
def _clean_blackboard():
    py_trees.blackboard.Blackboard.clear()
    yield
    py_trees.blackboard.Blackboard.clear()


@pytest.fixture
def rng():
    return np.random.default_rng(1234)
