"""Shared by the reproduction's tests: reading the HTML report back (the ``html_check`` fixture)."""
from __future__ import annotations

import re
from html.parser import HTMLParser

import pytest


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.ids, self.links, self.text, self.figcaptions, self.badges = set(), [], [], 0, []
        self._in = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids.add(a["id"])
        if tag == "a" and a.get("href", "").startswith("#"):
            self.links.append(a["href"][1:])
        if tag == "figcaption":
            self.figcaptions += 1
        if tag == "span" and "verdict" in (a.get("class") or ""):
            self.badges.append(a.get("style", ""))
        self._in.append(tag)

    def handle_endtag(self, tag):
        if self._in:
            self._in.pop()

    def handle_data(self, data):
        if not (self._in and self._in[-1] in ("style", "script")):
            self.text.append(data)


def parse(html_text: str) -> _Page:
    p = _Page()
    p.feed(html_text)
    return p


def assert_readable(page: _Page):
    text = " ".join(page.text)
    assert not re.search(r"\bNone\b", text), re.search(r".{60}\bNone\b.{60}", text)
    assert "{'" not in text and "': " not in text, "a Python dict reached the page"
    assert not re.search(r"\bnan\b", text) and "-0.00%" not in text
    missing = [l for l in page.links if l not in page.ids]
    assert not missing, f"contents links without a target: {missing}"




@pytest.fixture()
def html_check():
    """``(parse, assert_readable)``: parse an HTML page; assert no Python repr (None, dicts, nan,
    -0.00%) in its text and that every in-page link has a target."""
    return parse, assert_readable
