"""Titles, descriptions and a picture for links to the book shared elsewhere (Open Graph and the page description).

Each page gets ``<meta name="description">`` and ``og:title``, ``og:description``, ``og:type``, ``og:site_name``;
when the site's address is known (``html_baseurl``, set by the Pages workflow through ``BOOK_SITE_URL``), also
``og:url`` and ``og:image``, which must be absolute. The description is the page's first paragraph, cut at a word
near 200 characters. Every page also names the icon phones use for a link on the home screen.
"""

import re
from html import escape

from docutils import nodes

IMAGE = "_static/share-card.png"  # 1200 × 630, drawn by tools/draw_identity.py
TOUCH_ICON = "_static/apple-touch-icon.png"  # 180 × 180, the icon a phone puts on its home screen
LENGTH = 200


GREEK = dict(zip(["alpha", "beta", "gamma", "delta", "epsilon", "theta", "lambda", "mu", "pi", "sigma"], "αβγδεθλμπσ"))


def plain_math(tex: str) -> str:
    """Inline TeX as a preview can show it: '\\theta_{\\text{old}}' -> 'θ_old', 'L^{CLIP}' -> 'L^CLIP'; other commands
    (\\text, \\hat, \\mathrm, ...) are dropped and their argument kept."""
    text = re.sub(r"\\([A-Za-z]+)\s*", lambda m: GREEK.get(m[1], ""), tex)
    return re.sub(r"\s+", " ", text.replace("{", "").replace("}", "")).strip()


def plain_text(node) -> str:
    """A paragraph's text with its inline math written plainly."""
    if isinstance(node, nodes.math):
        return plain_math(node.astext())
    if isinstance(node, nodes.Text):
        return str(node)
    return "".join(plain_text(child) for child in node.children)


def first_paragraph(doctree) -> str:
    for paragraph in doctree.findall(nodes.paragraph):
        text = re.sub(r"\s+", " ", plain_text(paragraph)).strip()
        if len(text) >= 40:  # skip captions and one-line labels
            return text
    return ""


def shorten(text: str, length: int = LENGTH) -> str:
    if len(text) <= length:
        return text
    cut = text[: length - 1].rsplit(" ", 1)[0].rstrip(",;:")
    return cut + "…"


def _meta(attribute: str, key: str, value: str) -> str:
    return f'<meta {attribute}="{escape(key, quote=True)}" content="{escape(value, quote=True)}" />\n'


def _add_meta(app, pagename, templatename, context, doctree):
    if doctree is None:  # search, genindex: pages without a document
        return
    site_title = app.config.html_title or app.config.project
    title = re.sub(r"<[^>]+>", "", context.get("title", "")) or site_title
    description = shorten(first_paragraph(doctree))
    tags = _meta("property", "og:title", title if title == site_title else f"{title} · {site_title}")
    tags += _meta("property", "og:type", "website" if pagename == app.config.root_doc else "article")
    tags += _meta("property", "og:site_name", site_title)
    if description:
        tags += _meta("name", "description", description)
        tags += _meta("property", "og:description", description)
    base = app.config.html_baseurl
    if base:
        base = base.rstrip("/") + "/"
        tags += _meta("property", "og:url", f"{base}{pagename}.html")
        tags += _meta("property", "og:image", base + IMAGE)
        tags += _meta("property", "og:image:alt", "The minippo logo, PPO's clipped objective, beside the title")
        tags += _meta("name", "twitter:card", "summary_large_image")
    tags += f'<link rel="apple-touch-icon" href="{escape(context["pathto"](TOUCH_ICON, 1), quote=True)}" />\n'
    context["metatags"] = context.get("metatags", "") + tags


def setup(app):
    app.connect("html-page-context", _add_meta)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
