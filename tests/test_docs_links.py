"""Every relative link and image in ``docs/`` and every page of the site's navigation exists.

``mkdocs build --strict`` refuses the same links, but only where mkdocs is installed (the ``docs``
extra) and only when its warnings are not silenced: ``--quiet`` drops them before strict mode counts
them, which is how a broken image in a decision record passed CI. This check needs no mkdocs.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

_FENCE = re.compile(r"^(```|~~~).*?^\1[^\n]*$", re.S | re.M)
_INLINE_CODE = re.compile(r"`[^`\n]*`")
_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_HTML = re.compile(r"<(?:img|a)\b[^>]*?\b(?:src|href)\s*=\s*[\"']([^\"']+)[\"']", re.I)
_REF_DEF = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+\"[^\"]*\")?\s*$", re.M)


def links(text: str) -> list[str]:
    """The link and image targets of a Markdown text, outside code blocks and inline code."""
    text = _INLINE_CODE.sub("", _FENCE.sub("", text))
    return _LINK.findall(text) + _HTML.findall(text) + _REF_DEF.findall(text)


def broken_links(page: Path, docs: Path = DOCS) -> list[str]:
    """The relative targets of ``page`` that are not files of ``docs`` (absolute site paths too:
    mkdocs.yml makes them warnings, and strict mode makes warnings errors)."""
    bad = []
    for target in links(page.read_text(encoding="utf-8")):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith("#"):
            continue   # http:, https:, mailto:, an anchor on the same page
        path = target.split("#", 1)[0].split("?", 1)[0]
        if path.startswith("/"):
            bad.append(f"{target} (absolute path)")
            continue
        dest = (page.parent / path).resolve()
        try:
            dest.relative_to(docs.resolve())
        except ValueError:
            bad.append(f"{target} (outside docs/)")
            continue
        if not (dest.is_file() or (dest.is_dir() and (dest / "index.md").is_file())):
            bad.append(target)
    return bad


PAGES = sorted(DOCS.rglob("*.md"))


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(DOCS)) for p in PAGES])
def test_relative_links_exist(page):
    assert broken_links(page) == [], f"{page.relative_to(ROOT)}: broken links"


def test_nav_pages_exist():
    nav = re.findall(r":\s*([\w./-]+\.md)\s*$", (ROOT / "mkdocs.yml").read_text(), re.M)
    assert nav, "no pages found in mkdocs.yml's nav"
    missing = [p for p in nav if not (DOCS / p).is_file()]
    assert missing == []


def test_the_check_finds_a_broken_image(tmp_path):
    """The check itself: a broken image, a broken link, a link out of docs/ and an absolute path
    are found; links in code, external links, anchors and existing files are not."""
    (tmp_path / "img").mkdir()
    (tmp_path / "img" / "a.png").write_bytes(b"")
    (tmp_path / "sub").mkdir()
    page = tmp_path / "sub" / "p.md"
    page.write_text("![ok](../img/a.png) ![bad](img/a.png) [x](../nope.md#s) [y](../../outside.md) [z](/abs.md)\n"
                    "[web](https://example.org) [here](#top) `[code](missing.md)`\n"
                    "```\n![fenced](missing.png)\n```\n<img src=\"../img/missing.svg\">\n")
    assert broken_links(page, tmp_path) == ["img/a.png", "../nope.md#s", "../../outside.md (outside docs/)",
                                            "/abs.md (absolute path)", "../img/missing.svg"]


def test_ci_does_not_silence_the_docs_build():
    """``mkdocs build --strict --quiet`` passes with a broken link (quiet drops the warnings strict
    mode counts): CI must build the site without ``--quiet``."""
    ci = (ROOT / ".ci" / "run").read_text()
    builds = [ln for ln in ci.splitlines() if "mkdocs build" in ln and not ln.lstrip().startswith("#")]
    assert builds and all("--strict" in ln and "--quiet" not in ln and " -q" not in ln for ln in builds)
