"""docs/PAPERS.md against the committed study outputs in docs/papers/results/ (fast: JSON only).

Every row of a results table in docs/PAPERS.md names its evidence in the last column: the
results folder (first code span, e.g. `calib-002`) and the keys of its ``results.json``
(further code spans, dotted paths into ``result``; ``*`` takes every item of a list or dict,
``name=value`` the items of a list whose field ``name`` is ``value``).
Each number printed in the row's "ours" cell must equal one of the values under those keys,
within the rounding of its printed digits, in the units of the file or scaled by 100 (fraction
to %), 10³ (m to mm, mm to µm), 10⁶ (m to µm), 10¹² (m² to µm²) or 180/π (rad to degrees). A
folder of a sweep (``python -m pipeline sweep``) holds ``sweep.csv`` instead; its keys are
column names. A row without evidence says so in words and prints no number of ours.
"""

from __future__ import annotations

import csv
import json
import math
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from pipeline import cli
from pipeline.papers import registry as studies

ROOT = Path(__file__).resolve().parents[2]
PAPERS = ROOT / "docs" / "PAPERS.md"
RESULTS = ROOT / "docs" / "papers" / "results"
SCALES = (1.0, 100.0, 1e3, 1e6, 1e12, 180.0 / math.pi)
CODE = re.compile(r"`([^`]+)`")
#: a printed number: sign, digits, decimals, an optional "·10⁷"-style exponent
NUMBER = re.compile(r"(?<![\w.])[−-]?\d+(?:\.\d+)?(?:·10([⁻]?[⁰¹²³⁴⁵⁶⁷⁸⁹]+))?")
PIPE = re.compile(r"(?<!\\)\|")          # a cell border, not an escaped \| inside a cell
SUPERSCRIPT = str.maketrans("⁻⁰¹²³⁴⁵⁶⁷⁸⁹", "-0123456789")


def table_rows(text: str) -> Iterator[tuple[str, list[str]]]:
    """(row label, cells) of every table whose header's last column is "evidence"."""
    header: list[str] | None = None
    for line in text.splitlines():
        if not line.startswith("|"):
            header = None
            continue
        cells = [c.strip() for c in PIPE.split(line.strip().strip("|"))]
        if header is None:
            header = cells
            continue
        if set(line) <= set("|-: ") or header[-1] != "evidence":
            continue
        yield f"{cells[0]} / {cells[1]}", dict(zip(header, cells, strict=False)) | {"_cells": cells}


def lookup(node: object, path: str) -> Iterator[float]:
    """Every number under the dotted ``path`` of ``node`` (``*``: all items; a dict key may
    itself hold dots, e.g. ``headline.kuka_kr15.tcp_vs_heuristic``)."""
    yield from _walk(node, path.split("."), path)


def _walk(node: object, parts: list[str], path: str) -> Iterator[float]:
    if not parts:
        yield from flatten(node)
        return
    head = parts[0]
    if head == "*":
        items = list(node.values()) if isinstance(node, dict) else node if isinstance(node, list) else []
        for child in items:
            yield from _walk(child, parts[1:], path)
    elif "=" in head and isinstance(node, list):
        field, _, wanted = head.partition("=")
        children = [item for item in node if isinstance(item, dict) and str(item.get(field)) == wanted]
        if not children:
            raise KeyError(path)
        for child in children:
            yield from _walk(child, parts[1:], path)
    elif isinstance(node, dict):
        for k in range(1, len(parts) + 1):
            key = ".".join(parts[:k])
            if key in node:
                yield from _walk(node[key], parts[k:], path)
                return
        raise KeyError(path)
    elif isinstance(node, list):
        yield from _walk(node[int(head)], parts[1:], path)
    else:
        raise KeyError(path)


def flatten(node: object) -> Iterator[float]:
    if isinstance(node, bool):
        return
    if isinstance(node, int | float):
        yield float(node)
    elif isinstance(node, dict):
        for v in node.values():
            yield from flatten(v)
    elif isinstance(node, list):
        for v in node:
            yield from flatten(v)


def printed_numbers(cell: str) -> list[tuple[float, float]]:
    """(value, half unit of the last printed digit) of each number in ``cell``."""
    out = []
    for m in NUMBER.finditer(cell):
        text = m.group(0).replace("−", "-")
        mantissa = text.split("·")[0]
        decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
        power = int(m.group(1).translate(SUPERSCRIPT)) if m.group(1) else 0
        out.append((float(mantissa) * 10.0 ** power, 0.5 * 10.0 ** (power - decimals)))
    return out


def matches(value: float, half_ulp: float, candidates: list[float]) -> bool:
    return any(math.isclose(abs(value), abs(c) * s, abs_tol=half_ulp * 1.0001 + 1e-12)
               for c in candidates for s in SCALES if math.isfinite(c))


def rows() -> list[tuple[str, dict]]:
    return list(table_rows(PAPERS.read_text(encoding="utf-8")))


def test_papers_md_has_evidence_tables():
    assert len(rows()) >= 20


@pytest.mark.parametrize(("label", "row"), rows(), ids=[r[0][:60] for r in rows()])
def test_each_number_of_ours_is_in_its_results_file(label, row):
    evidence = CODE.findall(row["evidence"])
    ours = row["ours"]
    if not evidence:
        assert not printed_numbers(ours), f"{label}: numbers of ours without a results file"
        return
    folder, keys = RESULTS / evidence[0], evidence[1:]
    if (folder / "sweep.csv").is_file():
        with open(folder / "sweep.csv", encoding="utf-8") as fh:
            table = list(csv.DictReader(fh))
        candidates = [float(r[k]) for k in keys for r in table if r.get(k) not in (None, "")]
    else:
        data = json.loads((folder / "results.json").read_text(encoding="utf-8"))
        assert data["variant"] in ("full", "quick", "custom") and data["command"].startswith("python -m pipeline study")
        assert (folder / "tables.md").is_file()
        candidates = [v for k in keys for v in lookup(data["result"], k)]
    assert keys and candidates, f"{label}: no values under {keys} in {folder}/results.json"
    for value, half_ulp in printed_numbers(ours):
        assert matches(value, half_ulp, candidates), f"{label}: {value} not in {folder.name}: {keys}"


def test_every_results_folder_states_its_command_and_variant():
    folders = [p.parent for p in RESULTS.rglob("results.json")]
    assert folders
    for folder in folders:
        data = json.loads((folder / "results.json").read_text(encoding="utf-8"))
        assert data["variant"] in ("full", "quick", "custom")
        head = (folder / "tables.md").read_text(encoding="utf-8").splitlines()[0]
        assert data["command"] in head and data["variant"] in head


def _demo_study(argv: list[str]) -> None:
    print("| a | b |\n|---|---|\n| 1 | 2 |")
    studies.save_result("demo", {"argv": argv, "gain": 0.5, "sem": float("nan")})


def test_study_results_folder_holds_the_printed_tables_and_the_result(tmp_path, monkeypatch, capsys):
    """``study NAME ARGS --results DIR``: DIR/tables.md is what the study printed, headed by the
    command and variant; DIR/results.json its result (non-finite numbers as null)."""
    monkeypatch.setitem(studies.STUDIES, "demo", f"{__name__}:_demo_study")
    monkeypatch.setattr(studies, "study_dir", lambda name, root=None: tmp_path / "data")
    (tmp_path / "data").mkdir()
    folder = tmp_path / "evidence"
    assert cli.main(["study", "demo", "--quick", "--results", str(folder)]) == 0
    data = json.loads((folder / "results.json").read_text(encoding="utf-8"))
    assert data["variant"] == "quick" and data["study"] == "demo"
    assert data["result"] == {"argv": ["--quick"], "gain": 0.5, "sem": None}
    tables = (folder / "tables.md").read_text(encoding="utf-8")
    assert data["command"] in tables.splitlines()[0] and "| 1 | 2 |" in tables
    assert (tmp_path / "data" / "result.json").is_file()          # the study's own output as before
    assert cli.main(["study", "demo", "--n", "3", "--results", str(folder)]) == 0
    assert json.loads((folder / "results.json").read_text(encoding="utf-8"))["variant"] == "custom"
    assert cli.main(["study", "demo", "--results"]) == 2
    assert "error: study: --results: expected a folder" in capsys.readouterr().err


def test_shallow_json_keeps_every_value_and_puts_deep_values_on_one_line():
    result = {"args": {"seeds": 3}, "rows": [{"seed": k, "error_m": [1e-3 * k, 2.5e-4], "tag": "a"} for k in range(3)],
              "empty": [], "nothing": None}
    text = studies.shallow_json(result, depth=2)
    assert json.loads(text) == result
    lines = text.splitlines()
    assert '  {"seed":1,"error_m":[0.001,0.00025],"tag":"a"},' in lines      # one row, one line
    assert ' "args": {' in lines and '  "seeds": 3' in lines                  # shallow levels indented
    with pytest.raises(ValueError):
        studies.shallow_json({"x": math.nan})                                 # no NaN in committed evidence
