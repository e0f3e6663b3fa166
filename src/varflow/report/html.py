"""Assembly of the self-contained HTML page.

The page uses inline CSS only, no JavaScript and no external resource: every image
is a ``data:image/png;base64`` URI and charts are inline SVG.  Every string that
comes from a file (names, paths, parameters, error messages) goes through
:func:`esc`.  Each ``<img>`` gets an ``id`` (``img-1``, ``img-2``, ... in page order),
its display size as ``width``/``height`` (the pixel size, times the smallest integer
that brings the longer side to :data:`MIN_DISPLAY_SIDE` for tiny images, drawn with
pixelated scaling) and a ``data-role`` naming what it shows
(``flow``, ``legend``, ``gt``, ``error``, ``colorbar``, ``trajectories``,
``displacement``, ``visibility``; input frames: ``frame0``, ``frame1`` and ``warped``
beside a single flow, ``frame`` beside a batch flow thumbnail), so the page can be
checked by a program.  Rows of images are ``<div class="thumbs">`` flex containers
that wrap; a ``<div class="pair">`` inside one keeps a frame and its flow together.
"""

from __future__ import annotations

import html
import logging
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from .figures import png_data_uri

__all__ = ["esc", "fmt", "Page", "table", "key_value_table", "bar_chart_svg", "BAR_COLOUR"]

logger = logging.getLogger(__name__)

#: Images with a longer side below this are shown enlarged by an integer factor.
MIN_DISPLAY_SIDE = 96
#: Fill colour of the bars of :func:`bar_chart_svg` (steel blue).
BAR_COLOUR = "#4682b4"

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 16px 24px;
       color: #1a1a1a; background: #ffffff; font-size: 14px; line-height: 1.4; }
h1 { font-size: 22px; margin: 0 0 4px 0; }
h2 { font-size: 18px; margin: 28px 0 6px 0; border-bottom: 1px solid #ccc; }
h3 { font-size: 15px; margin: 18px 0 6px 0; }
header p, .note { color: #444; margin: 2px 0; }
code { font-family: ui-monospace, Menlo, Consolas, monospace; font-size: 13px; }
table { border-collapse: collapse; margin: 6px 0 10px 0; }
th, td { border: 1px solid #d0d0d0; padding: 2px 8px; text-align: right; }
th { background: #f0f0f0; }
td.text, th.text { text-align: left; }
td.best { font-weight: bold; }
tr.summary td { border-top: 2px solid #888; }
.thumbs { display: flex; flex-wrap: wrap; gap: 10px; align-items: flex-start; }
.pair { display: flex; gap: 4px; align-items: flex-start; }
figure { margin: 0; display: table; min-width: 72px; }
figure img, figure svg { display: block; }
figure img { outline: 1px solid #b0b0b0; image-rendering: pixelated; }
figcaption { display: table-caption; caption-side: bottom; font-size: 12px; color: #333;
             padding-top: 2px; }
.warn { background: #fff0f0; border: 1px solid #e0a0a0; padding: 4px 8px; }
details { margin: 6px 0; }
summary { cursor: pointer; color: #224; }
"""


def esc(value: Any) -> str:
    """HTML-escape ``str(value)`` (quotes included)."""
    return html.escape(str(value), quote=True)


def fmt(value: Any, digits: int = 3) -> str:
    """Format a number for a table cell: ``digits`` decimals, ``—`` for None/NaN."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        v = float(value)
        if math.isnan(v):
            return "—"
        if math.isinf(v):
            return "∞" if v > 0 else "−∞"
        return f"{v:.{digits}f}"
    return str(value)


def table(header: Sequence[str], rows: Iterable[Sequence[Any]], *, n_text: int = 1,
          best: Sequence[set[int]] | None = None, summary_rows: int = 0,
          cls: str = "") -> str:
    """An HTML table; every cell is escaped.

    Parameters
    ----------
    header : sequence of str
    rows : iterable of sequence
        Cells; numbers are formatted with :func:`fmt` (3 decimals).
    n_text : int
        The first ``n_text`` columns are left-aligned text.
    best : sequence of set of int, optional
        Per row, the column indices to show in bold.
    summary_rows : int
        The last ``summary_rows`` rows get a separating rule.
    cls : str
        ``class`` attribute of the table.
    """
    rows = [list(r) for r in rows]
    out = [f'<table class="{esc(cls)}">' if cls else "<table>", "<thead><tr>"]
    for j, h in enumerate(header):
        out.append(f'<th class="text">{esc(h)}</th>' if j < n_text else f"<th>{esc(h)}</th>")
    out.append("</tr></thead><tbody>")
    for i, r in enumerate(rows):
        tr = ' class="summary"' if summary_rows and i >= len(rows) - summary_rows else ""
        out.append(f"<tr{tr}>")
        for j, c in enumerate(r):
            classes = []
            if j < n_text:
                classes.append("text")
            if best is not None and i < len(best) and j in best[i]:
                classes.append("best")
            attr = f' class="{" ".join(classes)}"' if classes else ""
            out.append(f"<td{attr}>{esc(fmt(c))}</td>")
        out.append("</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def key_value_table(items: Mapping[str, Any], cls: str = "params") -> str:
    """Two-column table ``key | value`` (values formatted with ``repr``-like text)."""
    rows = []
    for k, v in items.items():
        if isinstance(v, float):
            text = f"{v:.6g}"
        elif isinstance(v, dict | list | tuple):
            import json

            text = json.dumps(v, sort_keys=True, default=str)
        else:
            text = str(v)
        rows.append((k, text))
    return table(("name", "value"), rows, n_text=2, cls=cls)


def bar_chart_svg(labels: Sequence[str], values: Sequence[float], *, unit: str,
                  title: str, width: int = 520) -> str:
    """Horizontal bar chart as inline SVG (one bar per label, value printed at its end).

    Parameters
    ----------
    labels : sequence of str
    values : sequence of float
        Non-finite values get no bar and the text ``n/a``.
    unit : str
        Appended to the printed values.
    title : str
        The chart's accessible name and heading.
    width : int
        Width of the SVG in pixels.
    """
    bar_h, gap, left, right, top = 18, 6, 140, 90, 22
    height = top + len(labels) * (bar_h + gap) + 4
    finite = [v for v in values if math.isfinite(v)]
    vmax = max(finite) if finite and max(finite) > 0 else 1.0
    span = width - left - right
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" role="img" aria-label="{esc(title)}" '
        f'class="chart">',
        f'<text x="0" y="14" font-size="13" font-weight="bold">{esc(title)}</text>',
    ]
    for i, (label, v) in enumerate(zip(labels, values, strict=True)):
        y = top + i * (bar_h + gap)
        parts.append(f'<text x="{left - 6}" y="{y + bar_h - 5}" font-size="12" '
                     f'text-anchor="end">{esc(label)}</text>')
        if math.isfinite(v):
            w = max(1.0, span * max(v, 0.0) / vmax)
            parts.append(f'<rect x="{left}" y="{y}" width="{w:.1f}" height="{bar_h}" '
                         f'fill="{BAR_COLOUR}" data-value="{v:.6g}"/>')
            text = f"{fmt(v)} {unit}".strip()
        else:
            w = 0.0
            text = "n/a"
        parts.append(f'<text x="{left + w + 4:.1f}" y="{y + bar_h - 5}" '
                     f'font-size="12">{esc(text)}</text>')
    parts.append("</svg>")
    return "".join(parts)


class Page:
    """Collects the body of a report and renders the complete document.

    Parameters
    ----------
    title : str
        Page title (escaped).
    """

    def __init__(self, title: str) -> None:
        self.title = title
        self.parts: list[str] = []
        self.n_images = 0
        self.image_bytes = 0

    def add(self, fragment: str) -> None:
        """Append an HTML fragment (already escaped)."""
        self.parts.append(fragment)

    def heading(self, text: str, level: int = 2, anchor: str | None = None) -> None:
        """Append ``<hN>`` with escaped text."""
        attr = f' id="{esc(anchor)}"' if anchor else ""
        self.parts.append(f"<h{level}{attr}>{esc(text)}</h{level}>")

    def para(self, text: str, cls: str = "note") -> None:
        """Append a paragraph of escaped text."""
        self.parts.append(f'<p class="{esc(cls)}">{esc(text)}</p>')

    def image(self, image: np.ndarray, *, role: str, caption: str | None = None,
              alt: str | None = None, extra: Mapping[str, Any] | None = None) -> str:
        """An ``<figure><img></figure>`` fragment with the image inlined as a PNG URI.

        Parameters
        ----------
        image : ndarray, shape (H, W, 3), uint8
        role : str
            Value of ``data-role``.
        caption : str, optional
            Escaped into ``<figcaption>``.
        alt : str, optional
            Alternative text (default: the caption or the role).
        extra : mapping, optional
            More ``data-*`` attributes (names without the prefix).

        Returns
        -------
        str
            The fragment (not appended; put it where it belongs with :meth:`add`).
        """
        self.n_images += 1
        uri = png_data_uri(image)
        self.image_bytes += len(uri)
        h, w = image.shape[:2]
        zoom = max(1, math.ceil(MIN_DISPLAY_SIDE / max(h, w)))
        attrs = "".join(f' data-{esc(k)}="{esc(v)}"' for k, v in (extra or {}).items())
        cap = f"<figcaption>{esc(caption)}</figcaption>" if caption else ""
        return (f'<figure><img id="img-{self.n_images}" src="{uri}" width="{w * zoom}" '
                f'height="{h * zoom}" alt="{esc(alt or caption or role)}" '
                f'data-role="{esc(role)}"{attrs}>{cap}</figure>')

    def render(self, header_lines: Sequence[str]) -> str:
        """The complete HTML document.

        Parameters
        ----------
        header_lines : sequence of str
            Plain-text lines shown under the title (escaped).
        """
        head = "".join(f"<p>{esc(line)}</p>" for line in header_lines)
        return (
            "<!DOCTYPE html>\n"
            '<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
            "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; "
            "img-src data:; style-src 'unsafe-inline'\">\n"
            f"<title>{esc(self.title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n"
            f"<header><h1>{esc(self.title)}</h1>{head}</header>\n<main>\n"
            + "\n".join(self.parts)
            + "\n</main>\n</body>\n</html>\n"
        )
