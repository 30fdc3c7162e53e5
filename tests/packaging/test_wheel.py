"""The package stands on its own: a wheel built from this checkout, installed outside it, loads
the shipped reference clutch, simulates, reads the ClutchState typestore and answers
`clutch-sim --help`, with the checkout not importable."""
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from clutch_model import load_model, simulate

REPO = Path(__file__).resolve().parents[2]

PROBE = r"""
import sys, json
import numpy as np
import clutch_model
from clutch_model import load_model, simulate
from clutch_model.formats.typestore import typestore
assert {repo!r} not in clutch_model.__file__, clutch_model.__file__
m = load_model(None)
t = np.arange(0.0, 0.1 + 1e-12, 0.001)
r = simulate(m, t, 8000.0, 5.0, 60.0)
ts = typestore()
fields = [f[0] for f in ts.get_msgdef("clutch_msgs/msg/ClutchState").fields]
print(json.dumps({{"file": clutch_model.__file__, "torque": r.torque_nm.tolist(),
                  "pack": r.pack_temperature_c.tolist(), "fields": fields}}))
"""


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("wheel")
    wheels, target, src = tmp / "wheels", tmp / "site", tmp / "src"
    # build from a clean copy of the sources: setuptools builds in the source tree, and a stale
    # build/ there could slip deleted modules into the wheel
    shutil.copytree(REPO, src, symlinks=True, ignore=shutil.ignore_patterns(
        ".git", ".venv", "build", "dist", "*.egg-info", "__pycache__", ".numba_cache", ".pytest_cache",
        "bags", "out", "runs"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                    "-w", str(wheels), str(src)], check=True, capture_output=True, timeout=300)
    (wheel,) = wheels.glob("clutch_sim-*.whl")
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target),
                    str(wheel)], check=True, capture_output=True, timeout=300)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(target)
    env["NUMBA_CACHE_DIR"] = str(tmp / "numba_cache")
    return wheel, target, env, tmp


def _run(args, env, cwd):
    return subprocess.run([sys.executable, "-P", *args], env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def test_wheel_carries_the_reference_clutch_and_the_message(installed):
    wheel, _, _, _ = installed
    names = zipfile.ZipFile(wheel).namelist()
    assert "clutch_model/data/reference_clutch.yaml" in names
    assert "clutch_model/data/ClutchState.msg" in names
    assert not any(n.startswith(("tests/", "bench/", "bags/")) for n in names)
    # the packaged file is the real content, byte for byte what config/ points users at
    packaged = zipfile.ZipFile(wheel).read("clutch_model/data/reference_clutch.yaml")
    assert packaged == (REPO / "config" / "reference_clutch.yaml").read_bytes()


def test_installed_wheel_loads_default_clutch_and_simulates(installed):
    import json

    _, target, env, tmp = installed
    p = _run(["-c", PROBE.format(repo=str(REPO))], env, tmp)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["file"].startswith(str(target))
    # same numbers as the checkout's code on the same inputs
    t = np.arange(0.0, 0.1 + 1e-12, 0.001)
    ref = simulate(load_model(None), t, 8000.0, 5.0, 60.0)
    np.testing.assert_allclose(out["torque"], ref.torque_nm, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out["pack"], ref.pack_temperature_c, rtol=1e-12, atol=1e-12)
    assert out["torque"][-1] > 100.0
    assert "clutch_torque" in out["fields"] and "locked" in out["fields"]


def test_installed_wheel_cli_help(installed):
    _, target, env, tmp = installed
    script = target / "bin" / "clutch-sim"          # the console script pip wrote for the wheel
    assert script.is_file()
    p = subprocess.run([str(script), "--help"], env=env, cwd=tmp, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "usage: clutch-sim" in p.stdout and "replay" in p.stdout and "diagnose" in p.stdout
    assert "Traceback" not in p.stderr


def test_config_reference_clutch_is_the_packaged_file():
    cfg = REPO / "config" / "reference_clutch.yaml"
    assert cfg.is_symlink() and cfg.resolve() == (REPO / "clutch_model" / "data" / "reference_clutch.yaml")


def test_packaged_message_equals_the_rosidl_source():
    assert ((REPO / "clutch_model" / "data" / "ClutchState.msg").read_bytes()
            == (REPO / "msg_defs" / "clutch_msgs" / "msg" / "ClutchState.msg").read_bytes())
