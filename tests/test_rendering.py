"""Renderer choice per client: EGL when the plugin loads, idempotent, survives id reuse."""

import pybullet as p
import pytest

from suture_bt.sim.rendering import load_renderer


def test_load_renderer_is_idempotent_and_per_client():
    c = p.connect(p.DIRECT)
    try:
        kind = load_renderer(c)
        assert kind in ("egl", "tiny")
        assert load_renderer(c) == kind
    finally:
        p.disconnect(c)
    c2 = p.connect(p.DIRECT)  # usually reuses the id: must load the plugin again
    try:
        assert load_renderer(c2) == kind
    finally:
        p.disconnect(c2)
    with pytest.raises(ValueError, match="not connected"):
        load_renderer(c2)


def test_tiny_fallback_by_environment(monkeypatch):
    monkeypatch.setenv("SUTURE_BT_RENDERER", "tiny")
    c = p.connect(p.DIRECT)
    try:
        assert load_renderer(c) == "tiny"
    finally:
        p.disconnect(c)
