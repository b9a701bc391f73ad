"""docs/PAPERS.md against the committed study outputs in docs/papers/results/ (fast: JSON only).

Every row of a results table in docs/PAPERS.md names its evidence in the last column: the
results folder (first code span, e.g. `calib-002`) and the keys of its ``results.json``
(further code spans, dotted paths into ``result``; ``*`` takes every item of a list or dict,
``name=value`` the items of a list whose field ``name`` is ``value``).
Each number printed in the row's "ours" cell is matched to ONE value under those keys, in order: the
first number to the first value that equals it under the first key that holds one, each further
number to a later value of the same key (after the value its predecessor took, in the file's order)
or to a value of a later key (never an earlier key, never an earlier value): a row prints its
numbers in the order of its keys and, within a key, in the order the file holds them. A number
equals a value within the rounding of its printed digits, with its sign, in the units of the file or
scaled by 100 (fraction to %), 10³ (m to mm, mm to µm), 10⁶ (m to µm), 10¹² (m² to µm²) or 180/π
(rad to degrees); a number moved by one unit in its last digit fails unless it lands on a later
value of the same key (:func:`test_a_moved_digit_fails`). Sample labels ("30 poses") must be
settings or values of the study. The numbers of the "verdict" (or "status") cell must each be a
value under the row's keys or of the study's settings, a number printed in another cell of the row
or in a "paper" cell of the file, or the ratio or relative difference of two numbers printed in its
"paper", "ours" and verdict cells; references ("Table 5", "Fig. 2", "KR 500") are not figures. A
folder of a sweep (``python -m pipeline sweep``) holds ``sweep.csv`` instead; its keys are column
names. A row without evidence says so in words and prints no number of ours.
"""

from __future__ import annotations

import csv
import functools
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
#: a reference or a name, not a figure: "Table 5", "Fig. 2", "§3.3", "step 3", "eq. 28", "KR 500"
REFERENCE = re.compile(r"(?:Tables?|Fig\.|§|step|eq\.|KR) ?$")
#: a label of the sample a figure is taken on ("at 30 poses", "0 / 1 / 2 iterations"): a setting, not a result
LABEL = re.compile(r"^(?: / \d+)* (?:poses|iterations)")
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


def printed_numbers(cell: str, skip: re.Pattern[str] | None = None,
                    skip_after: re.Pattern[str] | None = None) -> list[tuple[float, float]]:
    """(value, half unit of the last printed digit) of each number in ``cell``; numbers whose text
    before matches ``skip`` or after matches ``skip_after`` are left out."""
    out = []
    for m in NUMBER.finditer(cell):
        if (skip is not None and skip.search(cell[: m.start()])) or (
                skip_after is not None and skip_after.search(cell[m.end():])):
            continue
        text = m.group(0).replace("−", "-")
        mantissa = text.split("·")[0]
        decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
        power = int(m.group(1).translate(SUPERSCRIPT)) if m.group(1) else 0
        out.append((float(mantissa) * 10.0 ** power, 0.5 * 10.0 ** (power - decimals)))
    return out


def matches(value: float, half_ulp: float, candidates: list[float], signed: bool = True) -> bool:
    """``value`` (printed with rounding ``half_ulp``) is one of ``candidates`` at one of the scales;
    with ``signed`` its sign too (a zero matches either)."""
    return any(math.isclose(value if signed else abs(value), (c if signed else abs(c)) * s,
                            abs_tol=half_ulp * 1.0001 + 1e-12)
               for c in candidates for s in SCALES if math.isfinite(c))


def ordered_mismatch(printed: list[tuple[float, float]], key_values: list[list[float]]) -> tuple[float, int] | None:
    """The first printed number (value, its position) that breaks the matching of the module doc:
    number i goes to the first value it equals under key k (the key of number i − 1 or a later one)
    at an index j after the index number i − 1 took under that same key (any index under a key not
    yet used). None when all match."""
    k, last = 0, -1                     # the key of the previous match and its index under that key
    for i, (value, half_ulp) in enumerate(printed):
        while k < len(key_values):
            j = next((j for j, v in enumerate(key_values[k]) if j > last and matches(value, half_ulp, [v])), None)
            if j is not None:
                last = j
                break
            k, last = k + 1, -1
        if k == len(key_values):
            return value, i
    return None


def derived(numbers: list[float]) -> list[float]:
    """Ratios and relative differences (%) of every pair of printed numbers."""
    out = []
    for a in numbers:
        for b in numbers:
            if a and b:
                out += [a / b, 100.0 * (a / b - 1.0), 100.0 * (1.0 - a / b)]
    return out


def verdict_mismatch(row: dict, key_values: list[list[float]], settings: list[float]) -> float | None:
    """The first number of the verdict (or status) cell the row does not account for (module doc;
    ``settings``: the values of the study's arguments, e.g. its pose counts; references such as
    "Table 5" are not figures)."""
    cell = row.get("verdict", row.get("status", ""))
    others = [v for name, text in row.items() if name not in ("verdict", "status", "evidence", "_cells")
              for v, _ in printed_numbers(text)] + PAPER_NUMBERS
    pair = [abs(v) for name in ("paper", "ours", "verdict", "status") for v, _ in printed_numbers(row.get(name, ""))]
    ratios = derived(pair)
    flat = [v for values in key_values for v in values] + settings
    for value, half_ulp in printed_numbers(cell, REFERENCE):
        if matches(value, half_ulp, flat, signed=False) or any(math.isclose(abs(value), abs(o), abs_tol=half_ulp)
                                                                for o in others):
            continue
        # a ratio or percentage of rounded numbers: within its rounding plus 1.5 % of the ratio
        if any(math.isclose(abs(value), abs(r), rel_tol=0.015, abs_tol=half_ulp * 1.0001) for r in ratios):
            continue
        return value
    return None


def evidence_values(row: dict) -> tuple[list[str], list[list[float]], list[float]] | None:
    """The row's keys, the values under each and the study's settings (the values of its ``args``;
    None: the row names no evidence)."""
    evidence = CODE.findall(row["evidence"])
    if not evidence:
        return None
    folder, keys = RESULTS / evidence[0], evidence[1:]
    if (folder / "sweep.csv").is_file():
        with open(folder / "sweep.csv", encoding="utf-8") as fh:
            table = list(csv.DictReader(fh))
        return keys, [[float(r[k]) for r in table if r.get(k) not in (None, "")] for k in keys], []
    data = results_json(folder)
    assert data["variant"] in ("full", "quick", "custom") and data["command"].startswith("python -m pipeline study")
    assert (folder / "tables.md").is_file()
    return keys, [list(lookup(data["result"], k)) for k in keys], list(flatten(data["result"].get("args", {})))


@functools.cache
def results_json(folder: Path) -> dict:
    """A results folder's ``results.json``, read once per test session."""
    return json.loads((folder / "results.json").read_text(encoding="utf-8"))


def row_problem(label: str, row: dict) -> str | None:
    """Why the row's numbers are not its evidence's (module doc), None when they are."""
    found = evidence_values(row)
    ours = printed_numbers(row["ours"], REFERENCE, LABEL)
    if found is None:
        return f"{label}: numbers of ours without a results file" if ours else None
    keys, key_values, settings = found
    for value, half_ulp in printed_numbers(row["ours"], REFERENCE):
        anywhere = settings + [v for vs in key_values for v in vs]
        if (value, half_ulp) not in ours and not matches(value, half_ulp, anywhere):
            return f"{label}: {value} poses is not a setting of the study"
    if not keys or not any(key_values):
        return f"{label}: no values under {keys}"
    bad = ordered_mismatch(ours, key_values)
    if bad is not None:
        return f"{label}: number {bad[1] + 1} of ours, {bad[0]}, is under none of {keys} at or after its predecessor's"
    wrong = verdict_mismatch(row, key_values, settings)
    if wrong is not None:
        return f"{label}: {wrong} in the verdict is neither evidence nor a number of the row"
    return None


def rows() -> list[tuple[str, dict]]:
    return list(table_rows(PAPERS.read_text(encoding="utf-8")))


#: every number of a "paper" cell of the file: a verdict may quote the papers' figures of another row
PAPER_NUMBERS = [v for _, row in rows() for v, _ in printed_numbers(row.get("paper", ""))]


def test_papers_md_has_evidence_tables():
    assert len(rows()) >= 20


@pytest.mark.parametrize(("label", "row"), rows(), ids=[r[0][:60] for r in rows()])
def test_each_number_of_ours_is_in_its_results_file(label, row):
    assert row_problem(label, row) is None, row_problem(label, row)


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


def moved(cell: str, index: int, step: int) -> str:
    """``cell`` with its ``index``-th number moved by ``step`` units of its last printed digit."""
    m = list(NUMBER.finditer(cell))[index]
    text = m.group(0)
    mantissa, _, exponent = text.partition("·")
    sign = "−" if mantissa.startswith(("−", "-")) else ""
    digits = mantissa.lstrip("−-")
    decimals = len(digits.split(".")[1]) if "." in digits else 0
    units = round(float(digits) * 10**decimals) + step
    if units < 0:
        return cell
    new = f"{units / 10**decimals:.{decimals}f}"
    return cell[: m.start()] + sign + new + ("·" + exponent if exponent else "") + cell[m.end():]


def moved_rows() -> list[tuple[str, dict, int, int]]:
    out = []
    for label, row in rows():
        if not CODE.findall(row["evidence"]):
            continue
        kept = {(m.start(), m.group(0)) for m in NUMBER.finditer(row["ours"])
                if not REFERENCE.search(row["ours"][: m.start()]) and not LABEL.search(row["ours"][m.end():])}
        for i, m in enumerate(NUMBER.finditer(row["ours"])):
            if (m.start(), m.group(0)) in kept:
                out += [(label, row, i, step) for step in (-1, 1)]
    return out


def test_a_moved_digit_fails():
    """A test of the test: every number of ours moved by one unit in its last printed digit, one at a
    time, makes its row fail, except where the moved number equals, within its printed rounding, a
    later value of the same key and the numbers after it still find theirs (measured: 36 of 558
    moves, 6.5 %). Such a later value is
    - a close value of the same quantity: the standard errors of the searches under
      ``table_realistic.*.paired_diff`` (0.0011 … 0.0016 mm) and their means (0.0020 … 0.0036 mm,
      printed as the range "+0.002 … +0.004"); one design's ``before`` / ``after`` record, whose
      maxima and half peak-to-peak spans of the axes lie within 0.01 mm or 0.01° of each other
      (0.274 → 0.273 mm lands on ez's half peak-to-peak, 0.273 mm, after its maximum, 0.274 mm);
    - a value read at another of the scales: a Cardan error in rad times 100 (0.0038 rad as "0.38"),
      a fraction's standard error times 180/π ("0.1" from 0.00195) — most often for numbers printed
      with one or two significant digits.
    At most 8 % of the moves."""
    cases = moved_rows()
    assert len(cases) > 200
    passed = [(label, row["ours"], i, step) for label, row, i, step in cases
              if row_problem(label, row | {"ours": moved(row["ours"], i, step)}) is None]
    assert len(passed) <= 0.08 * len(cases), (len(passed), len(cases), passed[:5])


def test_the_wrong_detmax_figure_fails():
    """DETMAX × O3's mean on the realistic truth is 0.48047 mm in the file: printed 0.480 it passes,
    printed 0.481 (one unit off) it fails."""
    label, row = next((lb, r) for lb, r in rows() if "same index: BSAA better than DETMAX" in lb)
    assert row_problem(label, row) is None
    ours = row["ours"]
    assert "DETMAX 0.479 / 0.479 / 0.480 / 0.480 mm" in ours
    wrong = ours.replace("DETMAX 0.479 / 0.479 / 0.480 / 0.480 mm", "DETMAX 0.479 / 0.479 / 0.481 / 0.480 mm")
    assert row_problem(label, row | {"ours": wrong}) is not None


def test_a_number_under_an_earlier_key_fails():
    """Numbers are matched to the keys in their order: swapping two keys of a row whose numbers come
    from different keys makes it fail."""
    label, row = next((lb, r) for lb, r in rows() if lb.startswith("003 Table 4 (real UR10"))
    assert row_problem(label, row) is None
    codes = CODE.findall(row["evidence"])
    swapped = " ".join(f"`{c}`" for c in [codes[0], *codes[1:][::-1]])
    assert row_problem(label, row | {"evidence": swapped}) is not None
