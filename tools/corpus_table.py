"""The corpus table of ``docs/robots.md``: one row per arm of the corpus, rendered from the rows the
corpus test writes (``tests/anyarm/test_corpus.py``, one JSON file per arm under ``data/corpus/`` or
``$PIPELINE_CORPUS_DIR``), between the markers ``<!-- corpus table -->`` and ``<!-- /corpus table -->``.

    .venv/bin/python -m pytest -m "slow or study" tests/anyarm/test_corpus.py   # writes data/corpus/*.json
    .venv/bin/python tools/corpus_table.py   # rewrites the table in docs/robots.md
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- corpus table -->", "<!-- /corpus table -->"
COLUMNS = ("arm", "source", "format", "axes", "init / check / run exit", "placeholders", "held-out TCP error",
           "torque RMS / noise (worst joint)", "path error none / elastic FF", "CP / PtP duration",
           "gates failed", "CPU time")


def _num(value: object, fmt: str, scale: float = 1.0, unit: str = "") -> str:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return "–"
    return f"{value * scale:{fmt}}{unit}"


def _exit(row: dict, key: str) -> str:
    code = row.get(key)
    return "–" if code is None else str(code)


def table_row(row: dict) -> str:
    """One markdown row of the corpus table."""
    held = row.get("heldout_rms_after_m")
    cells = [
        f"`{row['arm']}`", row["source"], row["format"], str(row.get("axes", "–")),
        " / ".join(_exit(row, k) for k in ("init_exit", "check_exit", "run_exit")),
        ", ".join(row.get("placeholders") or []) or "none",
        _num(held, ".1f", 1e6, " µm"),
        _num(row.get("validation_rms_over_noise_max"), ".2f"),
        _num(row.get("path_error_none_over_elastic"), ".3g", 1.0, "×"),
        f"{_num(row.get('cp_duration_s'), '.3f', 1.0, ' s')} / {_num(row.get('ptp_duration_s'), '.3f', 1.0, ' s')}",
        str(len(row.get("failed_gates") or [])),
        _num(row.get("cpu_s"), ".0f", 1.0, " s"),
    ]
    return "| " + " | ".join(cells) + " |"


def render(rows: list[dict]) -> str:
    """The table (header, one row per arm in corpus order) and a line of totals."""
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS), *map(table_row, rows)]
    passed = sum(r.get("run_exit") == 0 and r.get("check_exit") == 0 and r.get("init_exit") == 0 for r in rows)
    cpu = sum(float(r.get("cpu_s") or 0.0) for r in rows)
    sources = len({r["source"] for r in rows})
    lines.append("")
    lines.append(f"{len(rows)} arms from {sources} sources, {passed} with exit 0 at every step; "
                 f"{cpu / 60:.1f} CPU-min in all (corpus profile, `configs/corpus.yaml`).")
    return "\n".join(lines)


def _ordered(rows: list[dict]) -> list[dict]:
    try:
        from pipeline.robot.public_arms import CORPUS
        order = {a.name: i for i, a in enumerate(CORPUS)}
    except ImportError:
        order = {}
    return sorted(rows, key=lambda r: (order.get(r["arm"], len(order)), r["arm"]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rows", type=Path,
                        default=Path(os.environ.get("PIPELINE_CORPUS_DIR", REPO / "data" / "corpus")))
    parser.add_argument("--doc", type=Path, default=REPO / "docs" / "robots.md")
    ns = parser.parse_args(argv)
    rows = _ordered([json.loads(p.read_text()) for p in sorted(ns.rows.glob("*.json"))])
    if not rows:
        parser.error(f"no corpus rows in {ns.rows} (run the corpus test first)")
    text = ns.doc.read_text()
    block = f"{BEGIN}\n{render(rows)}\n{END}"
    if BEGIN in text and END in text:
        text = re.sub(re.escape(BEGIN) + ".*?" + re.escape(END), lambda _: block, text, flags=re.S)
    else:
        text = text.rstrip("\n") + "\n\n## The arm corpus\n\n" + block + "\n"
    ns.doc.write_text(text)
    print(f"{ns.doc}: {len(rows)} corpus rows")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
