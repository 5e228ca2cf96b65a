"""The scene half of a recording: the world, the images and the plots, tick by tick.

Entities: ``world/phantom/ports/<port>`` (frame and 5 mm square), ``world/<arm>`` (links and
tip frame from measured joints + Δq̂, what the system believes), ``world/needle/estimate``
(each new estimate) and ``world/needle/predicted`` (moved with its holder),
``world/plan/...`` (the insertion arc and circle, presentation poses), ``world/camera/<eye>``
(frame, pinhole, and the images perception used with mask outline, keypoints and fitted
arc), ``camera/calibration/<arm>`` (the calibration image and jaw keypoints), ``plots/...``
(tracking error and PI output per joint). Ground truth, from the ``truth`` feed the front
door passes, only under ``ground_truth/``: the true needle and arms, the lateral error at each
port crossing, the strain at engaged ports, and a log of the crossings.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import rerun as rr

from suture_bt.calibration.jaw_keypoints import project_keypoints
from suture_bt.recording import images, scene
from suture_bt.recording.tree_sink import set_time, skill_nodes
from suture_bt.runtime.observer import Sink, TickRecord

#: Joint units for plots: degrees for revolute joints, millimetres for the insertion.
UNITS = np.array([180 / np.pi, 180 / np.pi, 1000.0, 180 / np.pi, 180 / np.pi, 180 / np.pi])
JOINT_NAMES = ["q1 °", "q2 °", "q3 mm", "q4 °", "q5 °", "q6 °"]
#: The 3D scene (arms, needle, truth) is logged every this many ticks (5: 10 Hz at 50 Hz);
#: the tree, the logs, the plots and the images every tick they change.
SCENE_EVERY = 5


class _Columns:
    """Scalars buffered per entity and sent as columns every ``size`` rows (cheaper than one
    ``log`` per row)."""

    def __init__(self, rec: rr.RecordingStream, size: int = 100):
        self.rec, self.size = rec, size
        self.rows: dict[str, tuple[list[int], list[float], list[np.ndarray]]] = {}

    def add(self, path: str, tick: int, sim_time: float, values: Any) -> None:
        ticks, times, vals = self.rows.setdefault(path, ([], [], []))
        ticks.append(int(tick))
        times.append(float(sim_time))
        vals.append(np.atleast_1d(np.asarray(values, dtype=float)))
        if len(ticks) >= self.size:
            self._send(path)

    def _send(self, path: str) -> None:
        ticks, times, vals = self.rows.pop(path)
        widths = [len(v) for v in vals]
        self.rec.send_columns(
            path,
            indexes=[
                rr.TimeColumn("tick", sequence=np.asarray(ticks)),
                rr.TimeColumn("sim_time", duration=np.asarray(times)),
            ],
            columns=rr.Scalars.columns(scalars=np.concatenate(vals)).partition(widths),
        )

    def flush(self) -> None:
        for path in list(self.rows):
            self._send(path)


class SceneSink(Sink):
    """Log the world of every tick to ``rec`` (see the module docstring)."""

    def __init__(self, rec: rr.RecordingStream, truth: Any = None, scene_every: int = SCENE_EVERY):
        self.rec, self.truth, self.scene_every = rec, truth, max(1, int(scene_every))
        self._belief: Any = None
        self._stamp: float | None = None
        self._frame: Any = None
        self._tap_count = 0
        self._seen: dict[int, Any] = {}  # id -> object already logged (checks, plans)
        self._crossings = 0
        self._strained: set[str] = set()
        self.columns = _Columns(rec)

    # ---------------------------------------------------------------- start
    def start(self, session: Any) -> None:
        rec, ctx = self.rec, session.context
        scene.log_static_scene(rec, ctx.phantom, ctx.camera.model)
        scene.log_pinholes(rec, ctx.camera.model, images.IMAGE_SCALE)
        scene.log_styles(rec, list(ctx.arms), ctx.needle)
        for arm in ctx.arms:
            for kind in ("tracking_error", "pi_output"):
                rec.log(f"plots/{kind}/{arm}", rr.SeriesLines(names=JOINT_NAMES), static=True)

    def tick(self, session: Any, record: TickRecord) -> None:
        set_time(self.rec, record.tick, record.sim_time)
        skills = skill_nodes(session, record)
        self._log_reports(session, skills)
        self._log_images(session, skills)
        with_scene = (record.tick - 1) % self.scene_every == 0
        if with_scene:
            self._log_world(session)
        self._log_plots(session, record)
        if self.truth is not None:
            self._log_truth(session, record, with_scene)

    # ---------------------------------------------------------------- reports and plans
    def _new(self, obj: Any) -> bool:
        if id(obj) in self._seen:
            return False
        self._seen[id(obj)] = obj  # kept alive so that its id is never reused
        return True

    def _log_reports(self, session: Any, skills: list) -> None:
        needle = session.context.needle
        for node in skills:
            report = node.skill.report
            arc = report.get("arc")
            if isinstance(arc, dict) and self._new(arc):
                pair = getattr(node, "pair", "x")
                T = np.asarray(arc["T_world_needle_entry"], dtype=float)
                scene.log_plan_arc(self.rec, f"world/plan/pair{pair}", needle, T)
            poses = report.get("presentation_poses")
            if isinstance(poses, list) and poses and self._new(poses):
                scene.log_poses(self.rec, "world/plan/presentation", poses, scene.PLAN)

    # ---------------------------------------------------------------- images
    def _log_images(self, session: Any, skills: list) -> None:
        ctx = session.context
        sensor = ctx.sensor
        frame = getattr(sensor, "last_frame", None)
        if frame is not None and frame is not self._frame:
            self._frame = frame
            estimate = getattr(sensor, "last_estimate", None)
            images.log_stereo(self.rec, frame, estimate, ctx.camera.model, ctx.needle)
        tap_count = getattr(ctx.camera, "captures", 0)
        if tap_count == self._tap_count:
            return
        self._tap_count = tap_count
        for node in skills:
            if getattr(node.skill, "name", "") == "calibrate arm":
                self._log_calibration(session, node.skill, ctx.camera.last)

    def _log_calibration(self, session: Any, skill: Any, frame: Any) -> None:
        ctx = session.context
        arm = ctx.arm(skill.arm_name)
        cam, T_base = ctx.camera.model.left, arm.base_frame()
        q, jaw = np.asarray(arm.arm.measured_jp(), dtype=float), arm.jaw_angle()
        kp = {"from measured joints": project_keypoints(q, jaw, T_base, cam)[0]}
        dq = skill.report.get("offset_estimate")
        if dq is not None:
            q_est = q.copy()
            q_est[:3] += np.asarray(dq, dtype=float)
            kp["with Δq̂"] = project_keypoints(q_est, jaw, T_base, cam)[0]
        images.log_calibration(self.rec, skill.arm_name, frame.left, kp)

    # ---------------------------------------------------------------- world and plots
    def _log_world(self, session: Any) -> None:
        ctx = session.context
        for name, arm in ctx.arms.items():
            q = arm.servo.estimated_jp()
            scene.log_arm(self.rec, f"world/{name}", arm.base_frame(), q)
        b = ctx.belief
        if b is not None and (b is not self._belief or b.stamp != self._stamp):
            self._belief, self._stamp = b, b.stamp
            scene.log_needle(self.rec, "world/needle/estimate", ctx.needle, b.T_world_needle)
        if b is not None and b.holder is not None:
            predicted = ctx.predicted_needle()
            if predicted is not None:
                path = "world/needle/predicted"
                scene.log_needle(self.rec, path, ctx.needle, predicted)

    def _log_plots(self, session: Any, record: TickRecord) -> None:
        for name, arm in session.context.arms.items():
            servo = arm.servo
            k, t = record.tick, record.sim_time
            self.columns.add(f"plots/tracking_error/{name}", k, t, UNITS * servo.error)
            self.columns.add(f"plots/pi_output/{name}", k, t, UNITS * servo.correction)

    def _log_truth(self, session: Any, record: TickRecord, with_scene: bool) -> None:
        truth, rec = self.truth, self.rec
        if with_scene:
            T = truth.needle_pose()
            if T is not None:
                scene.log_needle(rec, "ground_truth/world/needle", session.context.needle, T)
            for name, arm in session.context.arms.items():
                q = truth.joint_positions(name)
                scene.log_arm(rec, f"ground_truth/world/{name}", arm.base_frame(), q)
        crossings = truth.crossings()
        for c in crossings[self._crossings :]:
            rec.log(f"ground_truth/plots/lateral_mm/{c.port}", rr.Scalars([1e3 * c.lateral]))
            direction = "in" if c.inward else "out"
            rec.log(
                "ground_truth/log",
                rr.TextLog(
                    f"tip crossed {c.port} ({direction}) at {c.t:.2f} s, "
                    f"lateral {1e3 * c.lateral:.2f} mm",
                    level=rr.TextLogLevel.INFO,
                ),
            )
        self._crossings = len(crossings)
        strain = truth.strain()
        k, t = record.tick, record.sim_time
        for port in self._strained - set(strain):
            self.columns.add(f"ground_truth/plots/strain_mm/{port}", k, t, 0.0)
        for port, value in strain.items():
            self.columns.add(f"ground_truth/plots/strain_mm/{port}", k, t, 1e3 * value)
        self._strained = set(strain)

    # ---------------------------------------------------------------- end
    def close(self, session: Any) -> None:
        self.columns.flush()
