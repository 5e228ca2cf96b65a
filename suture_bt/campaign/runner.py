"""Run a campaign's trials: crash-isolated, time-budgeted, resumable, locally or on Ray.

Every trial runs in a process of its own (local backend: one child per trial, forked from a
server that has already imported the simulator; Ray: a task with ``max_retries=0``), so a trial
that raises, dies (``os._exit``, a segfault) or runs past its wall-clock budget becomes an
*error* outcome with its reason, and the campaign goes on. The driver records each outcome in
``DIR/trials/NNNN/`` and writes ``trial.json`` last (atomically): a trial with a
``trial.json`` is finished, and re-running the campaign skips it.
"""

from __future__ import annotations

import collections
import json
import multiprocessing
import os
import signal
import time
import traceback
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from multiprocessing.connection import wait as wait_any
from pathlib import Path
from typing import Any

from suture_bt.campaign.randomize import CampaignConfig, draw, trial_scene_dict, trial_seed

TrialFn = Callable[[dict[str, Any]], dict[str, Any]]
#: Default wall-clock budget of one trial (s): a healthy full suture takes 35-60 s alone,
#: the tree's own limit is 300 s of simulated time.
DEFAULT_BUDGET_S = 600.0
POLL_S = 0.2


@dataclass
class Outcome:
    """What came back from one trial: a payload, or an error with its reason."""

    spec: dict[str, Any]
    payload: dict[str, Any] | None
    error: str | None
    wall_s: float


def trial_specs(config: CampaignConfig, trials: int) -> list[dict[str, Any]]:
    """The specs of trials 0..trials-1 (everything a worker needs; plain data)."""
    return [
        {
            "index": i,
            "seed": trial_seed(config, i),
            "scene": trial_scene_dict(config, i),
            "draws": draw(config, i),
            "tree": config.tree,
            "oracle": config.oracle,
            "policy": config.policy,
            "max_sim_time": config.max_sim_time,
            "rerun": config.rerun,
        }
        for i in range(trials)
    ]


def trial_dir(out: Path, index: int) -> Path:
    """Where trial ``index`` keeps its files."""
    return out / "trials" / f"{index:04d}"


def finished(out: Path, index: int, retry_errors: bool = False) -> bool:
    """Whether trial ``index`` has a ``trial.json`` (and, with ``retry_errors``, ran)."""
    path = trial_dir(out, index) / "trial.json"
    if not path.is_file():
        return False
    if not retry_errors:
        return True
    try:
        return json.loads(path.read_text()).get("status") == "ok"
    except (OSError, ValueError):
        return False


def guarded(fn: TrialFn, spec: dict[str, Any]) -> dict[str, Any]:
    """Call ``fn(spec)``; an exception becomes an error payload with its reason."""
    try:
        return fn(spec)
    except BaseException as exc:  # noqa: BLE001 - a trial's exception is its outcome
        text = " ".join(str(exc).split()) or "(no message)"
        return {
            "status": "error",
            "reason": f"raised {type(exc).__name__}: {text}",
            "traceback": traceback.format_exc(limit=20),
        }


def _die_with_parent() -> None:
    """Linux: this child gets SIGKILL when its parent dies (a killed campaign leaves no
    orphan trials running). Best effort elsewhere."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _child(fn: TrialFn, spec: dict[str, Any], conn) -> None:
    """Body of a local trial process: run, send the payload, exit."""
    _die_with_parent()
    payload = guarded(fn, spec)
    try:
        conn.send(payload)
    except Exception as exc:  # noqa: BLE001 - e.g. an unpicklable payload
        conn.send({"status": "error", "reason": f"payload not sendable: {exc}"})
    conn.close()


def _exit_reason(code: int | None) -> str:
    """Words for a child's exit code."""
    if code is None:
        return "the trial process did not exit"
    if code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        return f"the trial process died ({name})"
    return f"the trial process exited with status {code} before reporting"


def _context(fn: TrialFn):
    """A forkserver context that preloads the trial function's module (so a child starts in
    milliseconds, not seconds), or spawn where there is no forkserver."""
    try:
        ctx = multiprocessing.get_context("forkserver")
        module = getattr(fn, "__module__", None) or getattr(fn, "func", fn).__module__
        ctx.set_forkserver_preload(["suture_bt.sim.quiet", module])
        return ctx
    except ValueError:
        return multiprocessing.get_context("spawn")


def run_local(
    specs: Iterable[dict[str, Any]],
    fn: TrialFn,
    on_outcome: Callable[[Outcome], None],
    workers: int = 2,
    budget_s: float = DEFAULT_BUDGET_S,
) -> None:
    """Run ``specs`` on ``workers`` child processes; ``on_outcome`` is called for each."""
    ctx = _context(fn)
    queue = collections.deque(specs)
    running: dict[Any, tuple[Any, dict[str, Any], float]] = {}
    try:
        while queue or running:
            while queue and len(running) < max(1, workers):
                spec = queue.popleft()
                recv, send = ctx.Pipe(duplex=False)
                proc = ctx.Process(target=_child, args=(fn, spec, send), daemon=True)
                proc.start()
                send.close()
                running[recv] = (proc, spec, time.monotonic())
            for conn in wait_any(list(running), timeout=POLL_S):
                proc, spec, t0 = running.pop(conn)
                try:
                    payload, error = conn.recv(), None
                except (EOFError, OSError):
                    payload = None
                proc.join(timeout=30)
                if proc.is_alive():
                    proc.kill()
                    proc.join()
                conn.close()
                if payload is None:
                    error = _exit_reason(proc.exitcode)
                on_outcome(Outcome(spec, payload, error, time.monotonic() - t0))
            now = time.monotonic()
            for conn, (proc, spec, t0) in list(running.items()):
                if now - t0 > budget_s:
                    running.pop(conn)
                    proc.kill()
                    proc.join()
                    conn.close()
                    reason = f"exceeded its time budget of {budget_s:g} s wall"
                    on_outcome(Outcome(spec, None, reason, now - t0))
    finally:
        for conn, (proc, _, _) in running.items():
            proc.kill()
            proc.join()
            conn.close()


def ray_trial(fn: TrialFn, spec: dict[str, Any], niceness: int) -> dict[str, Any]:
    """Body of a Ray task: run at the driver's priority (Ray starts its workers at nice 15,
    which on a busy machine starves a CPU-bound trial), then :func:`guarded`."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, niceness)
    except (OSError, AttributeError):
        pass  # not allowed here (lowering niceness needs privileges): keep Ray's
    return guarded(fn, spec)


def _ray_error(exc: BaseException) -> str:
    """Words for a Ray failure of a task (a dead worker, a cancelled task, ...)."""
    import ray

    if isinstance(exc, ray.exceptions.WorkerCrashedError | ray.exceptions.LocalRayletDiedError):
        return "the trial process died (Ray worker crashed)"
    text = " ".join(str(exc).split())[:300]
    return f"ray: {type(exc).__name__}: {text}"


def run_ray(
    specs: Iterable[dict[str, Any]],
    fn: TrialFn,
    on_outcome: Callable[[Outcome], None],
    address: str | None = None,
    budget_s: float = DEFAULT_BUDGET_S,
    max_in_flight: int | None = None,
) -> None:
    """Run ``specs`` as Ray tasks (``ray.remote``, one CPU each, no retries).

    Connects to ``address`` (``"auto"``, ``"ray://host:10001"``; None or ``"local"`` starts a
    local instance) unless Ray is already initialised. At most ``max_in_flight`` tasks (default:
    the cluster's CPUs) are submitted at once, so a task's budget runs from about its start
    (measured from submission: it includes a fresh worker's start-up).
    """
    try:
        import ray
    except ImportError:
        raise RuntimeError("the Ray backend needs ray: pip install 'suture-bt[ray]'") from None
    if not ray.is_initialized():
        ray.init(address=None if address in (None, "local") else address, log_to_driver=False)
    task = ray.remote(num_cpus=1, max_retries=0)(ray_trial)
    niceness = os.getpriority(os.PRIO_PROCESS, 0)
    cap = max_in_flight or max(1, int(ray.cluster_resources().get("CPU", 1)))
    queue = collections.deque(specs)
    pending: dict[Any, tuple[dict[str, Any], float]] = {}
    try:
        while queue or pending:
            while queue and len(pending) < cap:
                spec = queue.popleft()
                pending[task.remote(fn, spec, niceness)] = (spec, time.monotonic())
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=POLL_S)
            for ref in ready:
                spec, t0 = pending.pop(ref)
                try:
                    payload, error = ray.get(ref), None
                except Exception as exc:  # noqa: BLE001 - any task failure is an outcome
                    payload, error = None, _ray_error(exc)
                on_outcome(Outcome(spec, payload, error, time.monotonic() - t0))
            now = time.monotonic()
            for ref, (spec, t0) in list(pending.items()):
                if now - t0 > budget_s:
                    pending.pop(ref)
                    ray.cancel(ref, force=True)
                    reason = f"exceeded its time budget of {budget_s:g} s wall"
                    on_outcome(Outcome(spec, None, reason, now - t0))
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)


def default_workers() -> int:
    """One trial per CPU core."""
    return max(1, os.cpu_count() or 1)
