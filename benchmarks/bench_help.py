"""``--help`` of the benchmark scripts: their module docstring (what they measure and how to run
them) on standard output, exit code 0, before any argument is read as a robot or a run folder."""

from __future__ import annotations

import sys


def exit_on_help(doc: str | None) -> None:
    """Print ``doc`` and exit 0 when the command line asks for help (``-h``, ``--help``)."""
    if any(a in ("-h", "--help") for a in sys.argv[1:]):
        print(doc or "")
        raise SystemExit(0)
