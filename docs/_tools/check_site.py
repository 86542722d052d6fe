"""Fail if the built site shows a Sphinx role as raw text (``:class:`WardParams```); run by ``make docs``.

Usage: ``python docs/_tools/check_site.py SITE_DIR``. Prints one line per page
holding a raw role and exits 1, or prints the number of pages checked.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from sphinx_roles import RAW_ROLE


def main(site: Path) -> int:
    pages = sorted(site.rglob("*.html"))
    bad = [(p, len(RAW_ROLE.findall(p.read_text(encoding="utf-8")))) for p in pages]
    bad = [(p, n) for p, n in bad if n]
    for p, n in bad:
        print(f"{p.relative_to(site)}: {n} raw Sphinx role(s), e.g. ':class:`Name`' shown as text", file=sys.stderr)
    if not pages:
        print(f"{site}: no HTML pages; build the site first", file=sys.stderr)
        return 1
    if not bad:
        print(f"{len(pages)} pages, no raw Sphinx role")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "site")))
