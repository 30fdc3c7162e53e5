"""Live replay end to end: start the node, play bags into it in lock-step, record its
outputs, stop it, and score the live torque against the bags' measured torque.

    from clutch_sim_ros.live import live_replay
    summary = live_replay(["data/run_01"], "/clutch", "out/live.mcap")
"""
from __future__ import annotations

import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def node_command(namespace: str, *, sim_time: bool = True, clutch_params_file: Optional[str] = None,
                 params_file: Optional[str] = None, extra: tuple = ()) -> list[str]:
    """Command line of the node as a subprocess (``python -m clutch_sim_ros.node``, the
    module behind the console entry clutch-sim-node)."""
    from clutch_model.formats.bag_messages import normalize_namespace

    cmd = [sys.executable, "-m", "clutch_sim_ros.node", "--ros-args", "-r", f"__ns:={normalize_namespace(namespace) or '/'}"]
    if params_file:
        cmd += ["--params-file", str(params_file)]
    cmd += ["-p", f"use_sim_time:={'true' if sim_time else 'false'}", "-p", "publish_every:=1"]
    if clutch_params_file:
        cmd += ["-p", f"clutch_params_file:={Path(clutch_params_file).resolve()}"]
    return cmd + list(extra)


def node_env(domain_id: int) -> dict:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id))
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH", "")) if p)
    return env


def stop_process(proc: subprocess.Popen, timeout_s: float = 10.0) -> int:
    """SIGINT, then SIGKILL after ``timeout_s``; returns the exit code."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


def _rmse(a: np.ndarray, b: Optional[np.ndarray]) -> float:
    if b is None:
        return math.nan
    ok = np.isfinite(a) & np.isfinite(b)
    return float(np.sqrt(np.mean((a[ok] - b[ok]) ** 2))) if ok.any() else math.nan


def live_replay(bag_paths, namespace: str = "/clutch", out_mcap="out/live.mcap", *,
                clutch_params_file: Optional[str] = None, domain_id: Optional[int] = None,
                topics=None, progress: bool = True) -> dict:
    """Start clutch-sim-node (sim time) as a subprocess in ``namespace``, play the bags into it
    in lock-step (clutch-sim play --clock), record its outputs to ``out_mcap`` (overwritten),
    stop it, and return the RMSE of the live torque against each bag's /clutch/measured_torque
    (sampled on the replay grid, like offline replay):

        {"rmse_nm": float, "runs": [{"bag", "rows", "rmse_nm"}], "rows": int, "out": str,
         "retries": int, "wall_s": float, "node_exit_code": int}

    ``domain_id`` None = a random private ROS domain (the /clock of lock-step never reaches
    other nodes of the machine).
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from clutch_sim_ros.play import PlayError, Player
    from clutch_sim_ros.record import Recorder

    paths = [Path(p) for p in bag_paths]
    domain = int(domain_id) if domain_id is not None else random.randint(101, 200)
    log = tempfile.TemporaryFile(mode="w+")
    proc = subprocess.Popen(node_command(namespace, clutch_params_file=clutch_params_file),
                            env=node_env(domain), cwd=str(REPO), stdout=log, stderr=subprocess.STDOUT)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = Node("clutch_sim_live", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    recorder = None
    try:
        player = Player(node, executor, namespace, clock=True, progress=progress, discovery_timeout_s=60.0,
                        node_alive=lambda: proc.poll() is None)
        recorder = Recorder(node, out_mcap, namespace, log_time=lambda: player.sim_now_ns, overwrite=True,
                            gated=True, lockstep=True)
        player.recorder = recorder
        try:
            result = player.play(paths, topics)
        except Exception:
            if proc.poll() is not None:
                log.seek(0)
                tail = log.read().strip().splitlines()[-1:] or ["(no output)"]
                raise PlayError(f"clutch-sim-node exited with code {proc.returncode}: {tail[0]}") from None
            raise
        out = str(recorder.close())
    finally:
        if recorder is not None:
            recorder.close()
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
        code = stop_process(proc)
        log.close()
    runs, sq, n = [], 0.0, 0
    for bag in result.bags:
        rmse = _rmse(bag.torque_nm, bag.torque_measured_nm)
        runs.append({"bag": bag.name, "rows": bag.rows, "rmse_nm": rmse})
        if bag.torque_measured_nm is not None:
            ok = np.isfinite(bag.torque_nm) & np.isfinite(bag.torque_measured_nm)
            sq += float(np.sum((bag.torque_nm[ok] - bag.torque_measured_nm[ok]) ** 2))
            n += int(ok.sum())
    return {"rmse_nm": math.sqrt(sq / n) if n else math.nan, "runs": runs,
            "rows": sum(b.rows for b in result.bags), "out": out, "retries": result.retries,
            "wall_s": result.wall_s, "node_exit_code": code}
