"""The needle data generator renders labelled stereo pairs (via the CLI front door)."""

import json

import numpy as np

from suture_bt.cli import main
from suture_bt.datagen.needle_data import SCENARIOS, SimScene, grasp_transform
from suture_bt.geometry import NeedleModel
from suture_bt.perception.network import INPUT_SIZE
from suture_bt.perception.training import load_dataset


def test_grasp_transform_puts_the_grasped_point_behind_the_tip():
    model = NeedleModel()
    a = 2.5
    T = grasp_transform(model, a, flip=False)
    p = T[:3, :3] @ model.point_at(a) + T[:3, 3]
    np.testing.assert_allclose(p, (0, 0, -0.0015), atol=1e-12)
    Tf = grasp_transform(model, a, flip=True)
    np.testing.assert_allclose(Tf[:3, :3] @ model.point_at(a) + Tf[:3, 3], p, atol=1e-12)


def test_sampled_needles_never_pass_through_the_floor():
    # A needle cut by the floor shows a false end; no real scene does that (it once made 10 %
    # of the occluded benchmark scenes, where the sampler only checked the tissue).
    sim = SimScene(320, 240)
    try:
        rng = np.random.default_rng(4)
        line = sim.model.centerline(60)
        for _ in range(60):
            s = sim.sampler.sample(rng, zr=(0.08, 0.2))
            pts = line @ s.T_world_needle[:3, :3].T + s.T_world_needle[:3, 3]
            assert not sim.world.phantom.below_floor(pts).any(), s.scenario
    finally:
        sim.close()


def test_a_moved_phantom_is_drawn_told_and_sampled_where_it_was_moved():
    import pybullet as p

    from suture_bt.transforms import pose_to_transform

    sim = SimScene(320, 240)
    try:
        client = sim.world.client
        n_bodies = p.getNumBodies(physicsClientId=client)
        T = pose_to_transform((0.012, -0.008, 0.002), (0.03, -0.02, np.deg2rad(15.0)))
        sim.move_phantom(T)
        # The old tissue and floor are gone, the new ones drawn: as many bodies as before.
        assert p.getNumBodies(physicsClientId=client) == n_bodies
        np.testing.assert_allclose(sim.world.task.phantom.T_world_phantom, T)
        np.testing.assert_allclose(sim.sampler.T_world_phantom, T)
        port = sim.world.task.phantom.ports()[0]
        in_phantom = sim.world.task.phantom.ports_in_phantom[0].T
        np.testing.assert_allclose(port.position, (T @ in_phantom)[:3, 3], atol=1e-12)
        np.testing.assert_allclose(sim.sampler.ports[0].position, port.position)
        # The tissue bookkeeping moved with it: a point just below a moved port is inside.
        assert sim.world.phantom.inside_tissue((port.position - 0.001 * port.normal)[None])[0]
        # The port's dark square is drawn where the port now is (the tissue is pink).
        s = sim.sampler.sample(np.random.default_rng(3), scenario="resting", zr=(0.08, 0.2))
        sim.apply(s)
        rgb, _ = sim.render("left", s, np.random.default_rng(0))
        u, v = np.round(sim.stereo.left.project(port.position[None])[0]).astype(int)
        assert rgb[v, u].max() < 60
    finally:
        sim.close()


def test_data_command_writes_labelled_shards(tmp_path, capsys):
    assert main(["data", "needle", "--n", "2", "--out", str(tmp_path), "--seed", "3"]) == 0
    meta = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert meta["n_images"] == 4 and meta["seed"] == 3
    assert meta["variety"]["light_share"] == 0.0  # the shipped weights' data: default scene
    d = load_dataset(tmp_path)
    w, h = INPUT_SIZE
    assert d["images"].shape == (4, h, w, 3) and d["masks"].shape == (4, h, w)
    assert set(d["scenario"]) <= set(range(len(SCENARIOS)))
    for i in range(4):
        if d["visible"][i].any():
            assert d["masks"][i].max() > 0
        # Visible keypoints sit on (or within a pixel or two of) the needle's mask.
        for (u, v), vis in zip(d["keypoints"][i], d["visible"][i], strict=True):
            if vis:
                ui, vi = int(round(u)), int(round(v))
                assert d["masks"][i][max(vi - 3, 0) : vi + 4, max(ui - 3, 0) : ui + 4].max() > 0
    # Each image records its phantom block's pose choice and its light (direction, gain).
    assert d["phantom_moved"].shape == (4,) and d["light"].shape == (4, 4)
    np.testing.assert_allclose(np.linalg.norm(d["light"][:, :3], axis=1), 1.0)
    # Left and right images of a scene share the needle pose up to the 4 mm baseline.
    dp = d["pose_cam"][0][:3, 3] - d["pose_cam"][1][:3, 3]
    assert abs(np.linalg.norm(dp) - 0.004) < 1e-6


def test_varied_data_command_moves_the_phantom_and_tilts_the_light(tmp_path, capsys):
    assert main(["data", "needle-varied", "--n", "12", "--out", str(tmp_path), "--seed", "2"]) == 0
    meta = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert meta["variety"]["light_share"] == 0.5 and meta["variety"]["phantom_share"] == 0.6
    d = load_dataset(tmp_path)
    tilted = np.abs(d["light"][:, 2] - 1.0) > 1e-9
    assert tilted.any() and not tilted.all()
    # Both images of a scene share its light; a block of scenes shares its phantom pose.
    np.testing.assert_array_equal(d["light"][0::2], d["light"][1::2])
    assert len(set(d["phantom_moved"][:20].tolist())) == 1
