"""The repository documents its own interfaces and points nowhere outside itself."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"


def tracked_text_files():
    out = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
    for name in out.decode().split("\0"):
        p = REPO / name
        if not name or not p.is_file() or p.suffix in (".mcap", ".png", ".npz", ".db3"):
            continue
        try:
            yield name, p.read_text()
        except UnicodeDecodeError:
            continue


@pytest.mark.skipif(not (REPO / ".git").exists(), reason="not a git checkout")
def test_nothing_points_outside_the_repository():
    outside = re.compile(r"CONTRACT\.md|ROS_WHEELS|/work/shared|\.\./shared|shared/seed")
    hits = [f"{name}:{k + 1}" for name, text in tracked_text_files() if name != "tests/packaging/test_docs.py"
            for k, line in enumerate(text.splitlines()) if outside.search(line)]
    assert hits == []


def test_cli_page_is_generated_from_the_parsers():
    p = subprocess.run([sys.executable, str(REPO / "tools" / "gen_cli_doc.py"), "--check"], capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 0, p.stderr


def test_readme_links_every_doc_and_links_resolve():
    readme = (REPO / "README.md").read_text()
    links = set(re.findall(r"\]\((docs/[^)#]+)", readme))
    assert {f"docs/{p.name}" for p in DOCS.glob("*.md")} <= links
    assert all((REPO / link).is_file() for link in links)
    for page in DOCS.glob("*.md"):
        for link in re.findall(r"\]\(([^)#:]+\.md)", page.read_text()):
            assert (page.parent / link).is_file(), (page.name, link)


def test_every_mechanism_is_documented():
    from clutch_model.plant.mechanisms import CATALOG

    text = (DOCS / "mechanisms.md").read_text()
    for mid, mech in CATALOG.items():
        assert f"`{mid}`" in text, mid
        for name in mech.parameter_names():
            assert f"`{name}`" in text, (mid, name)


def test_every_state_field_and_node_parameter_is_documented():
    text = (DOCS / "interfaces.md").read_text()
    msg = (REPO / "msg_defs" / "clutch_msgs" / "msg" / "ClutchState.msg").read_text()
    fields = [line.split()[1] for line in msg.splitlines() if line.strip() and not line.startswith("#")]
    assert len(fields) == 15
    for f in fields:
        assert f"`{f}`" in text, f
    from clutch_sim_ros.params import SPEC      # the node's parameter table (no ROS import)

    params = [spec.name for spec in SPEC]
    assert "rate_hz" in params and "use_sim_time" in params
    for name in params:
        assert f"`{name}`" in text, name


def test_report_page_names_the_report_fields():
    text = (DOCS / "report.md").read_text()
    for key in ("cause", "causes", "parameters_ci95", "rmse_nm", "gain_pct", "held_out_runs", "candidates",
                "held_out_rmse_nm"):
        assert f"`{key}" in text or f'"{key}"' in text, key
