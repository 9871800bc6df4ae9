"""The HTML report of a run: one page, the same structure for every command.

A report is a folder: ``index.html`` and its PNG pictures beside it, so that it opens in
any browser from a disk or a share, with no server and no network. The page has

1. what was run (command, inputs, outputs, parameters, time);
2. a plan-view map of the classes the run wrote, and a hillshade of the terrain model
   when there is one;
3. tables (class shares per tile, test outcomes);
4. where the tests were not significant, as a map;
5. links to further pages (per-tile plots).

Every picture is checked when the page loads: a picture that fails to load is named in a
banner at the top of the page, instead of leaving a silent gap.
"""

from __future__ import annotations

import html
import json
from dataclasses import dataclass, field
from pathlib import Path

from .._shared._atomic import atomic_path

__all__ = ["ReportPage"]

_STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 0 auto;
       max-width: 1100px; padding: 1.5em; color: #212121; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f5f5f5; } td:first-child, th:first-child { text-align: left; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { color: #555; font-size: 0.9em; }
.params { font-family: ui-monospace, monospace; font-size: 0.85em; white-space: pre-wrap;
          background: #fafafa; padding: 0.6em; border: 1px solid #eee; }
#broken { display: none; background: #ffebee; color: #b71c1c; padding: 0.6em;
          border: 1px solid #e57373; }
"""

# Names every picture that did not load (a missing or unreadable PNG) in a banner.
_CHECK = """
window.addEventListener("load", function () {
  var bad = [];
  document.querySelectorAll("img").forEach(function (im) {
    if (!im.complete || im.naturalWidth === 0) { bad.push(im.getAttribute("src")); }
  });
  var box = document.getElementById("broken");
  if (bad.length) {
    box.textContent = "Pictures that could not be shown: " + bad.join(", ");
    box.style.display = "block";
  }
  document.body.setAttribute("data-images", bad.length ? "broken" : "ok");
});
"""


@dataclass
class ReportPage:
    """An HTML page assembled section by section, written with :meth:`write`.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> page = ReportPage("lidarstat moments", subtitle="tiles/ -> classified/")
    >>> page.section("Classes")
    >>> page.table(["class", "points"], [["ground", 1200], ["building", 300]])
    >>> out = page.write(pathlib.Path(tempfile.mkdtemp()))
    >>> out.name, "<td>ground</td>" in out.read_text()
    ('index.html', True)
    """

    title: str
    subtitle: str = ""
    _body: list[str] = field(default_factory=list)

    def section(self, heading: str, text: str = "") -> None:
        """Start a section (a level-2 heading), with an optional paragraph."""
        self._body.append(f"<h2>{html.escape(heading)}</h2>")
        if text:
            self.paragraph(text)

    def paragraph(self, text: str) -> None:
        """A paragraph of plain text."""
        self._body.append(f"<p>{html.escape(text)}</p>")

    def facts(self, items: dict) -> None:
        """A two-column table of names and values (inputs, outputs, seconds)."""
        self.table(["", ""], [[k, v] for k, v in items.items()], header=False)

    def parameters(self, params: dict) -> None:
        """The parameters of the run, as JSON."""
        text = json.dumps(params, indent=1, default=str, sort_keys=True)
        self._body.append(f"<div class='params'>{html.escape(text)}</div>")

    def table(self, columns, rows, *, header: bool = True) -> None:
        """A table; numbers are formatted to 4 significant digits."""
        def cell(v):
            if isinstance(v, float):
                v = f"{v:.4g}"
            return f"<td>{html.escape(str(v))}</td>"

        head = ("<tr>" + "".join(f"<th>{html.escape(str(c))}</th>" for c in columns)
                + "</tr>") if header else ""
        body = "".join("<tr>" + "".join(cell(v) for v in row) + "</tr>" for row in rows)
        self._body.append(f"<table>{head}{body}</table>")

    def figure(self, src: str, caption: str = "", *, alt: str | None = None) -> None:
        """A picture in the report folder (`src` relative to the page)."""
        alt = caption if alt is None else alt
        cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
        self._body.append(f"<figure><img src='{html.escape(src)}' alt='{html.escape(alt)}'>"
                          f"{cap}</figure>")

    def link(self, href: str, text: str) -> None:
        """A link to another page or file of the report."""
        self._body.append(f"<p><a href='{html.escape(href)}'>{html.escape(text)}</a></p>")

    def html(self) -> str:
        """The page."""
        sub = f"<p>{html.escape(self.subtitle)}</p>" if self.subtitle else ""
        return ("<!doctype html>\n<html lang='en'><head><meta charset='utf-8'>"
                "<meta name='viewport' content='width=device-width, initial-scale=1'>"
                f"<title>{html.escape(self.title)}</title><style>{_STYLE}</style>"
                f"<script>{_CHECK}</script></head><body>"
                f"<div id='broken'></div><h1>{html.escape(self.title)}</h1>{sub}"
                + "\n".join(self._body) + "</body></html>\n")

    def write(self, folder, name: str = "index.html") -> Path:
        """Write the page into `folder` (created if missing), atomically."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        out = folder / name
        with atomic_path(out) as tmp:
            tmp.write_text(self.html(), encoding="utf-8")
        return out
