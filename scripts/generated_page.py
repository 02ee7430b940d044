"""The write-or-check step the generated docs pages share: a page is a script's output,
never edited by hand, and `--check` (run in the suite) says when it has drifted."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(page: Path, render: Callable[[], str], doc: str | None) -> None:
    """Writes `render()` to `page`, or with --check exits 1 when `page` differs from it."""
    parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--check", action="store_true", help=f"exit 1 if {page.relative_to(ROOT)} is not up to date")
    args = parser.parse_args()
    text = render()
    script = Path(sys.argv[0]).resolve().relative_to(ROOT)
    if args.check:
        if not page.exists() or page.read_text() != text:
            sys.exit(f"{page.relative_to(ROOT)} is out of date: run python {script}")
        return
    page.write_text(text)
    print(f"wrote {page.relative_to(ROOT)}")
