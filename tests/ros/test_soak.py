"""30 s of bench/soak_node.py as a test: the node in sim time at 1 kHz on a hypothesis-
generated stream (NaN/inf bursts, out-of-range values, floods, stale gaps, the sim clock
jumping back) never publishes a non-finite value, never raises in a callback, rejects and
counts the bad inputs, restarts on clock jumps and is alive at the end. Timing figures
(on-time share, achieved rate, memory growth) are printed, not asserted."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from .conftest import REPO, subprocess_env

pytestmark = pytest.mark.ros


def test_soak_30s(domain_id, tmp_path):
    out = tmp_path / "soak.json"
    res = subprocess.run([sys.executable, str(REPO / "bench" / "soak_node.py"), "--duration", "30", "--seed", "7",
                          "--quiet", "--json", str(out)], env=subprocess_env(domain_id), cwd=str(REPO),
                         capture_output=True, text=True, timeout=400)
    print(res.stdout)
    assert out.is_file(), res.stderr[-2000:]
    r = json.loads(out.read_text())
    assert r["node_alive"] and r["node_exit_code"] == 0
    assert r["ticks"] > 0 and r["outputs_received"] > 0
    assert r["nonfinite_outputs"] == 0
    assert r["callback_errors"] == 0 and r["nonfinite_resets"] == 0
    assert all(n > 0 for n in r["rejected"].values()), r["rejected"]
    assert r["clock_jumps_back"] > 0 and r["clock_backs_sent"] > 0
    assert res.returncode == 0, res.stderr[-2000:]
