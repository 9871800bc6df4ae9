"""Sphinx configuration of the lidarstat manual.

Build (the test suite runs the same command, ``tests/test_docs.py``)::

    python -m pip install -e ".[docs]"
    sphinx-build -W --keep-going -b html docs docs/_build/html

Pages are Markdown (MyST). The API reference is generated at build time from each public
subpackage's ``__all__`` and its numpydoc docstrings (the ``lidarstat-api`` directive
below), so it cannot drift from the code. The CLI reference ``cli.md`` is generated from
the argument parser by ``python -m lidarstat.cli._reference docs/cli.md``.
"""

from __future__ import annotations

import enum
import importlib
import inspect
import pkgutil
import re
import sys
from pathlib import Path

from docutils.parsers.rst import Directive
from docutils.statemachine import StringList
from sphinx.pycode import ModuleAnalyzer

# The package from this checkout, before any installed copy.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

import lidarstat

project = "lidarstat"
author = "lidarstat developers"
copyright = "lidarstat developers"
version = release = lidarstat.__version__

extensions = [
    "myst_parser",
    "numpydoc",
    "sphinx.ext.autodoc",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "figures/*.py", "Thumbs.db", ".DS_Store"]
html_theme = "alabaster"  # Sphinx's own: no dependency beyond sphinx itself
html_title = f"lidarstat {release}"
html_static_path: list[str] = []
html_theme_options = {"description": "statistically tested geometry for LiDAR point clouds",
                      "fixed_sidebar": True, "show_relbars": True}

# --- MyST
myst_enable_extensions = ["dollarmath", "colon_fence"]
# Every heading down to level 4 gets an anchor, so pages can link to ``page.md#section``.
myst_heading_anchors = 4

# --- autodoc / numpydoc
autodoc_typehints = "none"  # numpydoc "Parameters" carry the types
autodoc_member_order = "bysource"
numpydoc_show_class_members = False  # members are documented by autodoc itself
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

# --- warnings
# The build runs with -W (warnings are errors) in the test suite, and nothing is
# suppressed: a broken cross-reference, a heading that skips a level or a docstring that
# is not valid reStructuredText fails it. A link to a repository file that is not a page
# (a benchmark script, a results JSON) resolves as a download when the file exists.
nitpicky = False


def _attribute_doc(package, name, obj):
    """The ``#:`` comment documenting data member `name` of `package`, and the module that
    holds it (autodoc looks only in the module named in the directive, while the public
    constants are defined in private modules, sometimes under another name:
    ``COVARIANCE_FIELDS`` is ``_covariance.FIELDS``); ``([], None)`` when there is none."""
    modnames = [package.__name__]
    modnames += [f"{package.__name__}.{m.name}"
                 for m in pkgutil.iter_modules(getattr(package, "__path__", []))]
    for modname in modnames:
        module = importlib.import_module(modname)
        if not any(value is obj for value in vars(module).values()):
            continue  # cannot hold it: its source need not be parsed
        docs = ModuleAnalyzer.for_module(modname).find_attr_docs()
        for (cls, attr), lines in docs.items():
            # an alias counts unless the value is a scalar that two names may share
            alias_ok = attr == name or not isinstance(obj, (int, float, str, bool))
            if not cls and lines and alias_ok and getattr(module, attr, None) is obj:
                return list(lines), modname
    return [], None


def _package(module):
    """``lidarstat.features`` for ``lidarstat.features._hk``."""
    return ".".join((module or "").split(".")[:2])


def _summary(doc_lines):
    """The first paragraph of a docstring, on one line."""
    para = []
    for line in doc_lines:
        if not line.strip():
            if para:
                break
            continue
        para.append(line.strip())
    return _escape_bars(" ".join(para)) or "(undocumented)"


class LidarstatAPI(Directive):
    """``.. lidarstat-api:: lidarstat.io``: a summary table and the documentation of every
    name in the module's ``__all__``, in that order.

    Classes are documented with their public members (enumerations with every code),
    functions with their signature, data with the ``#:`` comment of the private module
    that defines it (without its value, which is often a long table). A name re-exported from another public subpackage (e.g.
    ``lidarstat.classify.SurfaceType``, defined in ``lidarstat.features``) is documented
    in both places but indexed only where it is defined. The summary is each docstring's
    whole first paragraph (autosummary's first-sentence cut can split inline markup).
    """

    required_arguments = 1

    def run(self):
        modname = self.arguments[0]
        mod = importlib.import_module(modname)
        entries = []
        for name in mod.__all__:
            obj = getattr(mod, name)
            if inspect.isclass(obj) or callable(obj):
                doc, where = (inspect.getdoc(obj) or "").splitlines(), obj.__module__
            else:
                doc, where = _attribute_doc(mod, name, obj)
            entries.append((name, obj, doc, _package(where) not in ("", modname)))
        lines = [f".. automodule:: {modname}", "   :no-members:", "",
                 f".. currentmodule:: {modname}", "",
                 ".. list-table::", "   :widths: 30 70", ""]
        for name, obj, doc, _ in entries:
            lines += [f"   * - :obj:`{name}`", f"     - {_summary(doc)}"]
        lines.append("")
        for name, obj, doc, elsewhere in entries:
            if inspect.isclass(obj):
                lines += [f".. autoclass:: {name}", "   :members:", "   :show-inheritance:"]
                if issubclass(obj, enum.Enum):  # the codes are a contract: list every one
                    lines.append("   :undoc-members:")
            elif callable(obj):
                lines += [f".. autofunction:: {name}"]
            else:
                lines += [f".. py:data:: {name}", f"   :type: {type(obj).__name__}"]
            if elsewhere:
                lines.append("   :no-index:")
            lines.append("")
            if not (inspect.isclass(obj) or callable(obj)):
                lines += [f"   {_escape_bars(line)}" for line in doc] or ["   (undocumented)"]
                lines.append("")
        self.state_machine.insert_input(StringList(lines), f"<lidarstat-api {modname}>")
        return []


# Docstrings are written as plain text that also reads well in ``help()``: ``|k|`` there
# is an absolute value, which reStructuredText would take for a substitution reference.
# Bars outside literals, roles, doctest lines, literal blocks and tables are escaped.
_SPANS = re.compile(r"(:\w+:`[^`]*`|``.*?``|`[^`]*`)")


def _escape_bars(line):
    parts = _SPANS.split(line)
    return "".join(p if i % 2 else p.replace("|", r"\|") for i, p in enumerate(parts))


def escape_absolute_values(app, what, name, obj, options, lines):
    """``autodoc-process-docstring`` handler: escape the bars of absolute values."""
    literal_indent = None
    for i, line in enumerate(lines):
        stripped = line.lstrip()
        indent = len(line) - len(stripped)
        if literal_indent is not None:
            if stripped and indent <= literal_indent:
                literal_indent = None
            else:
                continue
        table_or_block = stripped == "|" or stripped.startswith(("| ", "+-", "+=")) or (
            stripped.startswith("|") and stripped.endswith("|") and stripped.count("|") > 2)
        if table_or_block or stripped.startswith((">>>", "...")) or "|" not in line:
            if line.rstrip().endswith("::"):
                literal_indent = indent
            continue
        lines[i] = _escape_bars(line)
        if line.rstrip().endswith("::"):
            literal_indent = indent


def setup(app):
    app.add_directive("lidarstat-api", LidarstatAPI)
    app.connect("autodoc-process-docstring", escape_absolute_values)
    return {"parallel_read_safe": True}
