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
