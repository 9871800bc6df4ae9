"""The manual: the generated CLI reference is current and the docs build without warnings."""

from __future__ import annotations

import importlib.util
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from lidarstat.cli._app import build_parser
from lidarstat.cli._reference import REGENERATE, cli_reference

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _subparsers(parser):
    for action in parser._actions:
        if action.__class__.__name__ == "_SubParsersAction":
            yield from action.choices.items()


def test_cli_reference_is_current():
    committed = (DOCS / "cli.md").read_text(encoding="utf-8")
    assert cli_reference() == committed, (
        f"docs/cli.md is out of date with the argument parser; regenerate it with "
        f"`{REGENERATE}` (from the repository root) and commit it")


def test_cli_reference_lists_every_option_of_every_command():
    text = cli_reference()
    for name, sub in _subparsers(build_parser()):
        section = text.split(f"## `lidarstat {name}`", 1)[1].split("\n## ", 1)[0]
        old = sub.get_default("_deprecated") or {}
        for action in sub._actions:
            if action.dest == "help":
                continue
            label = ", ".join(o for o in action.option_strings if o not in old) or action.dest
            row = next((r for r in section.splitlines() if r.startswith(f"| `{label}` |")), None)
            assert row is not None, f"{name}: {label} missing"
            for spelling in (o for o in action.option_strings if o in old):
                assert f"deprecated spelling, still accepted: {spelling}" in row


def test_cli_reference_escapes_table_cells():
    import argparse

    p = argparse.ArgumentParser(prog="tool")
    sub = p.add_subparsers(dest="command")
    s = sub.add_parser("cmd", help="a | b", description="Reads <file>.")
    s.add_argument("--level", type=float, default=0.5, help="p < 0.05 | *bold*")
    s.add_argument("--mode", choices=("a", "b"), nargs="?", const="a", help="mode")
    text = cli_reference(p)
    row = next(line for line in text.splitlines() if line.startswith("| `--level`"))
    assert row.count(" | ") == 3  # four cells: the pipe of the help is escaped
    assert r"p \< 0.05 \| \*bold\*" in row
    assert "`[{a,b}]`; alone: `a`" in text
    assert "tool cmd [options]" in text


def _example_commands():
    """Every ``lidarstat ...`` command line in the bash blocks of the user's pages."""
    pages = [ROOT / "README.md", *sorted(DOCS.glob("*.md")), DOCS / "methods" / "synthetic.md"]
    for page in pages:
        blocks = re.findall(r"```bash\n(.*?)```", page.read_text(encoding="utf-8"), re.DOTALL)
        for block in blocks:
            for line in block.splitlines():
                for part in line.split("#", 1)[0].split("&&"):
                    words = shlex.split(part)
                    if words[:1] == ["lidarstat"]:
                        yield f"{page.relative_to(ROOT)}: {part.strip()}", words[1:]


def test_example_commands_parse():
    # The examples of the README and the manual use options that exist, with valid values.
    examples = list(_example_commands())
    assert len(examples) > 20
    bad = []
    for where, argv in examples:
        try:
            build_parser().parse_args(argv)
        except SystemExit:
            bad.append(where)
    assert not bad, "example commands the parser refuses:\n" + "\n".join(bad)


def test_options_named_in_the_manual_exist():
    # Prose names options too (`--boundary grid`); each must be an option of some command.
    options = {o for _, sub in _subparsers(build_parser()) for a in sub._actions
               for o in a.option_strings}
    pages = [ROOT / "README.md", *sorted(p for p in DOCS.glob("*.md") if p.name != "cli.md"),
             DOCS / "methods" / "synthetic.md"]
    unknown = sorted({f"{p.relative_to(ROOT)}: {o}" for p in pages
                      for o in re.findall(r"`(--[a-z][a-z0-9-]*)", p.read_text(encoding="utf-8"))
                      if o not in options})
    assert not unknown, "options the parser does not have:\n" + "\n".join(unknown)


def test_readme_links_resolve():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    assert targets
    missing = [t for t in targets if "://" not in t and not (ROOT / t).exists()]
    assert not missing, f"README links to missing files: {missing}"


def test_fields_page_names_every_published_field():
    # The field tables the library publishes (name -> (dtype, meaning)) are what the
    # commands write; users' scripts rely on the names, so the manual must give each one.
    from lidarstat.classify import COVARIANCE_CLASS_FIELDS
    from lidarstat.features import COVARIANCE_FIELDS, FIELDS, JET_FIELDS
    from lidarstat.segment import RIDGE_FIELDS

    page = (DOCS / "fields.md").read_text(encoding="utf-8")
    tables = {"curvature": FIELDS, "covariance": COVARIANCE_FIELDS, "jets": JET_FIELDS,
              "covariance classes": COVARIANCE_CLASS_FIELDS, "ridges": RIDGE_FIELDS}
    missing = [f"{table}: {name}" for table, fields in tables.items() for name in fields
               if f"`{name}`" not in page]
    assert not missing, "fields not documented in docs/fields.md: " + ", ".join(missing)


@pytest.mark.parametrize("results", ["results_scaling.json", "results_real_resources.json"])
def test_performance_tables_are_their_results_files(results):
    # These tables are rendered by the script that writes the results file; a row edited by
    # hand (or pasted into the wrong table) would show figures no script regenerates.
    import json

    table = json.loads((ROOT / "benchmarks" / results).read_text())["markdown"].strip()
    page = (DOCS / "performance.md").read_text(encoding="utf-8")
    stale = [row for row in table.splitlines() if row not in page.splitlines()]
    assert not stale, f"docs/performance.md differs from {results}:\n" + "\n".join(stale)


def test_peer_table_is_its_results_files():
    # benchmarks/peers.py renders the table "Against the peers" from the results files;
    # the page must show the rows it renders, not figures of an earlier run.
    spec = importlib.util.spec_from_file_location("peers", ROOT / "benchmarks" / "peers.py")
    peers = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(peers)
    table = peers.table().strip()
    page = (DOCS / "performance.md").read_text(encoding="utf-8")
    assert len(table.splitlines()) > 2, "benchmarks/peers.py rendered no rows"
    stale = [row for row in table.splitlines() if row not in page.splitlines()]
    assert not stale, "docs/performance.md differs from benchmarks/peers.py:\n" + "\n".join(stale)


def test_no_development_history_in_the_manual():
    pages = [ROOT / "README.md", *sorted(DOCS.glob("*.md")), *sorted(DOCS.glob("methods/*.md"))]
    # The manual describes the software as it is; how it got there is in the CHANGELOG.
    # A results key named after a work session (an `_s` and its number) is history too.
    history = re.compile(r"\bsession|the lead\b|quiet machine|the old default|\w_s\d{1,2}(?!\d)",
                         re.IGNORECASE)
    found = [f"{p.relative_to(ROOT)}:{i}: {line.strip()}"
             for p in pages for i, line in enumerate(p.read_text().splitlines(), 1)
             if history.search(line)]
    assert not found, "development history in the manual:\n" + "\n".join(found)


def test_sphinx_builds_without_warnings(tmp_path):
    missing = [m for m in ("sphinx", "myst_parser", "numpydoc")
               if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"the docs need {', '.join(missing)} "
                    "(pip install -e '.[docs]'); not building the manual")
    out = tmp_path / "html"
    proc = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
         "-d", str(tmp_path / "doctrees"), str(DOCS), str(out)],
        check=False, capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, f"sphinx-build failed:\n{proc.stderr[-6000:]}"
    for page in ("index", "getting-started", "cli", "fields", "pipeline", "api/features",
                 "methods/curvature"):
        assert (out / f"{page}.html").is_file(), page
