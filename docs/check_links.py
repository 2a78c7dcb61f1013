"""Link check of the built site (``mkdocs build`` first): every internal ``href``/``src`` of every page must
name a file of the site, and every ``#anchor`` an ``id`` on the target page. External links (http, mailto)
are listed, not fetched (CI has no network). Exit 1 on a broken link.

``python docs/check_links.py [build/site]``
"""

from __future__ import annotations

import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit


class _Page(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.links: list[str] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if a.get("id"):
            self.ids.add(str(a["id"]))
        for key in ("href", "src"):
            if a.get(key) and not (tag == "link" and key == "href" and a.get("rel") in ("canonical",)):
                self.links.append(str(a[key]))


def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(errors="replace"))
    return page


def check(site: Path) -> tuple[int, int, list[str], set[str]]:
    pages = {p: _parse(p) for p in site.rglob("*.html")}
    broken, checked, external = [], 0, set()
    for path, page in pages.items():
        for link in page.links:
            parts = urlsplit(link)
            if parts.scheme in ("http", "https", "mailto", "data"):
                external.add(link)
                continue
            checked += 1
            if not parts.path:
                target = path
            elif parts.path.startswith("/"):  # 404.html links from the site's root
                target = (site / unquote(parts.path).lstrip("/")).resolve()
            else:
                target = (path.parent / unquote(parts.path)).resolve()
            if target.is_dir():
                target = target / "index.html"
            if not target.exists():
                broken.append(f"{path.relative_to(site)}: {link} (no such file)")
                continue
            if parts.fragment and target.suffix == ".html":
                ids = pages[target].ids if target in pages else _parse(target).ids
                if unquote(parts.fragment) not in ids:
                    broken.append(f"{path.relative_to(site)}: {link} (no anchor #{parts.fragment})")
    return len(pages), checked, broken, external


def main(argv: list[str]) -> int:
    site = Path(argv[0] if argv else "build/site").resolve()
    n_pages, checked, broken, external = check(site)
    for b in broken:
        print(f"broken: {b}")
    print(f"{n_pages} pages, {checked} internal links and images checked, {len(broken)} broken; "
          f"{len(external)} external links not fetched")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
