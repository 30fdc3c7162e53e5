"""`clutch-sim` entry point: a thin argparse layer over clutch_sim.commands.

Every subcommand lives in its own module under clutch_sim/commands/ with two functions,
``add_parser(subparsers)`` and ``run(args) -> int``; modules keep heavy imports inside run().
User errors (clutch_model.errors.ClutchSimError and OSError on user files) are caught here,
once, and printed as one line with a non-zero exit code; anything else is a defect, also one
line (exit code 3) unless CLUTCH_SIM_TRACEBACK is set.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys

COMMANDS = ["replay", "synth", "fit_friction", "fit_thermal", "calibrate", "montecarlo",
            "sensitivity", "diagnose", "play", "record", "driveline"]


def add_params_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--params", "--model", dest="params", metavar="FILE", default=None,
                        help="clutch parameter file (default: the shipped reference clutch RC-1)")


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2, as argparse does, without the usage block
        self.exit(2, f"clutch-sim: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="clutch-sim", description="Virtual wet clutch for eLSD controller development.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"clutch_sim.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"clutch_sim.commands.{name}":
                continue  # command not built yet
            raise
        module.add_parser(sub)
    return parser


def main(argv=None) -> int:
    """Console entry: ``_main`` with Ctrl-C at any point (imports, parsing, the command) ending
    in one line and exit code 130."""
    try:
        return _main(argv)
    except KeyboardInterrupt:
        from clutch_sim import interrupts

        interrupts.quiet()
        print("clutch-sim: interrupted", file=sys.stderr)
        return 130


def _main(argv=None) -> int:
    from clutch_model.errors import ClutchSimError

    from clutch_sim import interrupts

    parser = build_parser()
    args = parser.parse_args(argv)
    interrupts.install()
    from clutch_model.threads import limit_blas_threads

    limit_blas_threads()
    try:
        try:
            return int(args.func(args) or 0)
        except BaseException as exc:
            if interrupts.is_interrupt(exc):   # Ctrl-C, also wrapped (numba SystemError, Dask)
                raise KeyboardInterrupt from None
            raise
    except ClutchSimError as exc:
        print(f"clutch-sim {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except (FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError) as exc:
        print(f"clutch-sim {args.command}: error: {exc.strerror}: {exc.filename}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        interrupts.quiet()
        sys.stdout.flush()
        lead = "\n" if sys.stderr.isatty() else ""   # end a progress bar line first
        print(f"{lead}clutch-sim {args.command}: interrupted (files already written are kept)", file=sys.stderr)
        return 130
    except Exception as exc:        # a defect, not bad input: one line too, the traceback on request
        if os.environ.get("CLUTCH_SIM_TRACEBACK"):
            raise
        sys.stdout.flush()
        print(f"clutch-sim {args.command}: internal error: {type(exc).__name__}: {exc} (files already written "
              f"are kept; CLUTCH_SIM_TRACEBACK=1 shows where)", file=sys.stderr)
        return 3


if __name__ == "__main__":
    sys.exit(main())
