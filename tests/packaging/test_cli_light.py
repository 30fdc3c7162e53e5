"""`clutch-sim --help` and every `clutch-sim SUB --help` answer without loading the numerics
(numba, scipy, matplotlib) or ROS: checked in a fresh interpreter per command."""
import json
import subprocess
import sys

import pytest

from clutch_sim.cli import COMMANDS

HEAVY = ("numba", "scipy", "matplotlib", "rclpy", "dask", "SALib")
PROBE = """
import contextlib, io, json, sys
from clutch_sim.cli import main
out = io.StringIO()
with contextlib.redirect_stdout(out):
    try:
        main({argv!r})
        code = None
    except SystemExit as exc:
        code = exc.code
print(json.dumps({{"code": code, "help": out.getvalue(),
                  "loaded": sorted({{m.split('.')[0] for m in sys.modules}})}}))
"""


@pytest.mark.parametrize("argv", [["--help"]] + [[c.replace("_", "-"), "--help"] for c in COMMANDS],
                         ids=lambda a: " ".join(a))
def test_help_does_not_import_the_numerics(argv):
    p = subprocess.run([sys.executable, "-c", PROBE.format(argv=argv)], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0, p.stderr
    res = json.loads(p.stdout)
    assert res["code"] == 0
    assert res["help"].startswith("usage: "), res["help"][:200]
    heavy = [m for m in HEAVY if m in res["loaded"]]
    assert heavy == [], f"{' '.join(argv)} imported {heavy}"


DEFECT = """
import sys
import clutch_sim.commands.replay as command
def defect(args):
    print("written before the defect")
    raise RuntimeError("a defect deep in the numerics")
command.run = defect
from clutch_sim.cli import main
sys.exit(main(["replay", "--bag", "x", "--out", "y.csv"]))
"""


@pytest.mark.parametrize("traceback", [False, True])
def test_an_internal_error_ends_in_one_line_unless_the_traceback_is_asked_for(traceback):
    """A defect (not bad input) still ends in one line on stderr and exit code 3, with what the
    command printed before it kept; CLUTCH_SIM_TRACEBACK=1 shows the traceback instead."""
    import os

    env = {**os.environ, **({"CLUTCH_SIM_TRACEBACK": "1"} if traceback else {})}
    env.pop("CLUTCH_SIM_TRACEBACK", None) if not traceback else None
    p = subprocess.run([sys.executable, "-c", DEFECT], capture_output=True, text=True, timeout=120, env=env)
    assert "written before the defect" in p.stdout
    if traceback:
        assert p.returncode == 1 and "Traceback" in p.stderr
    else:
        assert p.returncode == 3, p.stderr
        assert p.stderr.strip().splitlines() == [
            "clutch-sim replay: internal error: RuntimeError: a defect deep in the numerics (files already "
            "written are kept; CLUTCH_SIM_TRACEBACK=1 shows where)"]
