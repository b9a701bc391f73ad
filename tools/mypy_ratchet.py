"""Type-check ``pipeline`` with mypy and fail when any file has more errors than its baseline.

The settings live in ``pyproject.toml`` ``[tool.mypy]``; ``tools/mypy_baseline.json`` holds the
number of errors each file had when the checker was introduced. A file may only go down: more
errors than its baseline (or any error in a file the baseline does not list) exits 1 and prints
the errors. When a file improves, ``--update`` writes the lower counts back.

    python tools/mypy_ratchet.py            # check
    python tools/mypy_ratchet.py --update   # rewrite the baseline from the current errors
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BASELINE = ROOT / "tools" / "mypy_baseline.json"
ERROR_LINE = re.compile(r"^(?P<path>[^:\s]+\.py):\d+(?::\d+)?: error: ")


def run_mypy() -> list[str]:
    """Run mypy with the project settings; return its error lines (exit 2 on a mypy crash)."""
    proc = subprocess.run([sys.executable, "-m", "mypy", "--no-error-summary", "--show-error-codes"],
                          cwd=ROOT, capture_output=True, text=True, check=False)
    if proc.returncode not in (0, 1) or (proc.returncode == 1 and not proc.stdout.strip()):
        sys.stderr.write(proc.stdout + proc.stderr)
        print("error: mypy: did not finish (see above)", file=sys.stderr)
        sys.exit(2)
    return [line for line in proc.stdout.splitlines() if ERROR_LINE.match(line)]


def count_by_file(lines: list[str]) -> dict[str, int]:
    """Errors per source file, keyed by the path mypy prints (relative to the repository)."""
    counts = Counter(m.group("path") for line in lines if (m := ERROR_LINE.match(line)))
    return dict(sorted(counts.items()))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--update", action="store_true", help="write the current counts as the new baseline")
    args = parser.parse_args(argv)
    lines = run_mypy()
    counts = count_by_file(lines)
    if args.update:
        BASELINE.write_text(json.dumps(counts, indent=1) + "\n")
        print(f"mypy baseline: {sum(counts.values())} errors in {len(counts)} files -> {BASELINE.relative_to(ROOT)}")
        return 0
    baseline: dict[str, int] = json.loads(BASELINE.read_text()) if BASELINE.exists() else {}
    worse = {path: n for path, n in counts.items() if n > baseline.get(path, 0)}
    better = {path: n for path, n in baseline.items() if counts.get(path, 0) < n}
    total, allowed = sum(counts.values()), sum(baseline.values())
    if worse:
        for line in lines:
            if ERROR_LINE.match(line) and line.split(":", 1)[0] in worse:
                print(line)
        for path, n in worse.items():
            print(f"error: {path}: mypy errors: {n}, baseline allows {baseline.get(path, 0)}", file=sys.stderr)
        return 1
    print(f"mypy: {total} errors (baseline {allowed}); no file got worse")
    if better:
        print(f"{len(better)} files improved: lower the baseline with `python tools/mypy_ratchet.py --update`")
    return 0


if __name__ == "__main__":
    sys.exit(main())
