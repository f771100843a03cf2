#!/usr/bin/env python3
"""Check the links of the built guide: every internal link and resource resolves.

    python3 scripts/guide/linkcheck.py docs/guide/book [--markdown README.md ...]

For every HTML page under the book: each `href` and `src` that is not external (http, https,
mailto) must name a file that exists, and its `#fragment`, when given, an `id` (or `name`) on
that page. External links are listed, not fetched (CI has no network beyond the registries).
With `--markdown FILE`, the relative links of those Markdown files (the README's links into the
guide) are checked against the source tree the same way (files only).

Exits 1 when a link is broken, listing each with the page it is on.
"""

import argparse
import html.parser
import pathlib
import re
import sys
import urllib.parse


class Links(html.parser.HTMLParser):
    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.links = []  # (attribute, value)
        self.ids = set()

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if value is None:
                continue
            if name in ("id",) or (name == "name" and tag == "a"):
                self.ids.add(value)
            if name in ("href", "src") and tag != "base":
                self.links.append((tag, value))


def parse(path, cache={}):
    if path not in cache:
        p = Links()
        p.feed(path.read_text(encoding="utf-8"))
        cache[path] = p
    return cache[path]


def is_external(url):
    scheme = urllib.parse.urlsplit(url).scheme
    return scheme in ("http", "https", "mailto", "ftp", "data", "javascript")


def check_book(book):
    broken, external, checked = [], set(), 0
    for page in sorted(book.rglob("*.html")):
        for tag, url in parse(page).links:
            if is_external(url):
                external.add(url)
                continue
            checked += 1
            parts = urllib.parse.urlsplit(url)
            target = page
            if parts.path:
                if parts.path.startswith("/"):
                    target = book / parts.path.lstrip("/")
                else:
                    target = (page.parent / urllib.parse.unquote(parts.path)).resolve()
                if target.is_dir():
                    target = target / "index.html"
                if not target.exists():
                    broken.append(f"{page.relative_to(book)}: {url}: no such file")
                    continue
            if parts.fragment and target.suffix == ".html":
                frag = urllib.parse.unquote(parts.fragment)
                if frag not in parse(target).ids:
                    broken.append(f"{page.relative_to(book)}: {url}: no #{frag} there")
    return broken, external, checked


MD_LINK = re.compile(r"\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def check_markdown(files):
    broken = []
    for f in files:
        text = f.read_text(encoding="utf-8")
        # Links inside code spans and blocks are not links.
        text = re.sub(r"```.*?```", "", text, flags=re.S)
        text = re.sub(r"`[^`\n]*`", "", text)
        for url in MD_LINK.findall(text):
            if is_external(url) or url.startswith("#"):
                continue
            path = urllib.parse.unquote(urllib.parse.urlsplit(url).path)
            if not (f.parent / path).exists():
                broken.append(f"{f}: {url}: no such file")
    return broken


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("book", type=pathlib.Path)
    ap.add_argument("--markdown", type=pathlib.Path, nargs="*", default=[])
    args = ap.parse_args()
    broken, external, checked = check_book(args.book)
    broken += check_markdown(args.markdown)
    for b in broken:
        print(f"broken link: {b}")
    for url in sorted(external):
        print(f"external (not fetched): {url}")
    print(
        f"guide links: {checked} internal checked, {len(external)} external listed, "
        f"{len(broken)} broken"
    )
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
