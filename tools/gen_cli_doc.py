"""Write docs/cli.md from the argparse parsers of `clutch-sim` (so the page cannot drift).

    python tools/gen_cli_doc.py           # rewrite docs/cli.md
    python tools/gen_cli_doc.py --check   # exit 1 if docs/cli.md is out of date
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "docs" / "cli.md"

HEADER = """\
# Command line: `clutch-sim`

Generated from the argument parsers by `python tools/gen_cli_doc.py` (a test checks it is
current). Conventions shared by every subcommand:

- `--params FILE` (alias `--model`) selects the clutch parameter file; the default is the shipped
  reference clutch RC-1. Any file of the same schema works, including fitted and extended models
  with a `mechanisms:` list ([mechanisms.md](mechanisms.md)), which every command applies.
- Bad input (missing or unreadable files, malformed bags or CSV, out-of-range options) ends with
  one line `clutch-sim COMMAND: error: REASON` on stderr and exit code 1 (2 for a malformed
  command line); no traceback. Files already written are kept; Ctrl-C ends with exit code 130.
  An internal error (a defect, not the input) also ends in one line, `clutch-sim COMMAND:
  internal error: ...`, exit code 3; `CLUTCH_SIM_TRACEBACK=1` shows the traceback instead.
- Long work shows a progress bar on stderr.
- Bag inputs and the replay grid are described in [bags.md](bags.md), the diagnosis report in
  [report.md](report.md).

"""


def render() -> str:
    os.environ["COLUMNS"] = "100"          # argparse wraps help to the terminal width
    sys.path.insert(0, str(REPO))
    from clutch_sim.cli import build_parser

    parser = build_parser()
    parser.prog = "clutch-sim"
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    parts = [HEADER, "## `clutch-sim`\n\n```\n", parser.format_help(), "```\n"]
    for name, p in sub.choices.items():
        parts += [f"\n## `clutch-sim {name}`\n\n```\n", p.format_help(), "```\n"]
    return "".join(parts)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Write docs/cli.md from the clutch-sim parsers.")
    ap.add_argument("--check", action="store_true", help="only check that docs/cli.md is current")
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        if not OUT.is_file() or OUT.read_text() != text:
            print(f"{OUT} is out of date: run python tools/gen_cli_doc.py", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
