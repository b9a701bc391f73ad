"""Picture of a run's headline for the README: the top of ``report.md`` (title, run line and the
``## Headline`` section up to the first stage section) rendered to PNG with headless Chromium.

    python tools/report_headline_png.py data/runs/rx130l-quick docs/img/report-headline.png
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import tempfile
from pathlib import Path

from markdown_it import MarkdownIt

CSS = """
body { font-family: 'DejaVu Sans', Helvetica, Arial, sans-serif; font-size: 14px; color: #1f2328;
       margin: 16px 22px; width: 1240px; background: #fff; }
h1 { font-size: 24px; border-bottom: 1px solid #d0d7de; padding-bottom: 6px; margin: 0 0 8px 0; }
h2 { font-size: 19px; border-bottom: 1px solid #d0d7de; padding-bottom: 4px; margin: 14px 0 8px 0; }
code { background: #eff1f3; padding: 1px 4px; border-radius: 4px; font-size: 12px; }
table { border-collapse: collapse; margin: 4px 0; }
th, td { border: 1px solid #d0d7de; padding: 3px 8px; font-size: 13px; }
th { background: #f6f8fa; }
"""


def headline_markdown(report_md: str) -> str:
    """The report's lines before its first stage section (``## `` other than ``## Headline``)."""
    out: list[str] = []
    for line in report_md.splitlines():
        if line.startswith("## ") and line.strip() != "## Headline":
            break
        out.append(line)
    return "\n".join(out) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("png", type=Path)
    ns = parser.parse_args()
    md = headline_markdown((ns.run_dir / "report.md").read_text(encoding="utf-8"))
    html = MarkdownIt("commonmark").enable("table").render(md)
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        raise SystemExit("error: chromium not found (apt-get install chromium)")
    with tempfile.TemporaryDirectory() as tmp:
        page = Path(tmp) / "headline.html"
        page.write_text(f"<!doctype html><html><head><meta charset='utf-8'><style>{CSS}</style></head>"
                        f"<body>{html}</body></html>", encoding="utf-8")
        subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                        f"--screenshot={ns.png.resolve()}", "--window-size=1290,570", page.as_uri()],
                       check=True, capture_output=True)
    print(f"wrote {ns.png}")


if __name__ == "__main__":
    main()
