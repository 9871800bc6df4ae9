"""The command-line reference (``docs/cli.md``), generated from the argument parser.

The manual's CLI page is written by walking :func:`lidarstat.cli._app.build_parser`:
every command with its usage line and description, and a table of every option (its
flags, the value it takes with the value's domain, its default and its help), one table
per argument group. It therefore cannot drift from the parser; the test suite
regenerates it in memory and compares it with the committed page
(``tests/test_docs.py``). Regenerate it after changing an option::

    python -m lidarstat.cli._reference docs/cli.md

Only the parser's own description is used; nothing is executed but the option types'
converters, on an invalid value, to read the domain from the message they give a user
(``must be a finite number > 0``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["cli_reference", "main"]

#: How to regenerate the page, stated in the page and in the test's failure message.
REGENERATE = "python -m lidarstat.cli._reference docs/cli.md"

_HEADER = """\
# Command-line reference

<!-- Generated from the argument parser by `{regenerate}`; do not edit by hand. -->

This page lists every command of `lidarstat`, with every option, the value it takes, its
default and its meaning; `lidarstat COMMAND --help` prints the same. It is generated from
the argument parser (regenerate it with `{regenerate}`), so it is complete by
construction. What the per-point fields written by each command mean is in
[Per-point output fields](fields.md); how each method works is in its method page.

Every option's value is checked before any file is read; a bad value gives one line
naming the option as typed and exit status 2, as does bad input data. Exit status 1 is an
internal error (one line; `-v` adds the traceback), 130 an interrupt (Ctrl-C), 143
SIGTERM; no partial output is left behind by any of them.
"""

#: Titles argparse gives its own groups (the first two: Python >= 3.10 and before).
_DEFAULT_TITLES = ("options", "optional arguments", "positional arguments")

# Values the converters are asked to convert to learn the domain from their message.
_PROBES = ("nan", "-1e308", "")


def _escape(text: str) -> str:
    """Text for a Markdown table cell (MyST): no pipes, HTML, emphasis or math."""
    text = " ".join(str(text).split())
    for ch in ("\\", "|", "<", ">", "*", "$"):
        text = text.replace(ch, "\\" + ch)
    return text


def _code(text: str) -> str:
    """``text`` as an inline code span for a table cell."""
    text = str(text).replace("|", "\\|")
    fence = "``" if "`" in text else "`"
    pad = " " if "`" in text else ""
    return f"{fence}{pad}{text}{pad}{fence}"


def _metavar(action: argparse.Action, positional: bool) -> str:
    """The value part of an option as argparse prints it (``RADIUS [RADIUS ...]``)."""
    if action.nargs == 0:
        return ""
    if action.metavar is not None:
        metavar = action.metavar
    elif action.choices is not None:
        metavar = "{" + ",".join(str(c) for c in action.choices) + "}"
    else:
        metavar = action.dest if positional else action.dest.upper()
    parts = metavar if isinstance(metavar, tuple) else None

    def one(i=0):
        return parts[i % len(parts)] if parts else metavar

    nargs = action.nargs
    if nargs is None:
        return one()
    if nargs == argparse.OPTIONAL:
        return f"[{one()}]"
    if nargs == argparse.ZERO_OR_MORE:
        return f"[{one()} ...]"
    if nargs == argparse.ONE_OR_MORE:
        return f"{one(0)} [{one(1) if parts else one()} ...]"
    if isinstance(nargs, int):
        return " ".join(one(i) for i in range(nargs))
    return one()


def _domain(action: argparse.Action) -> str:
    """What a valid value is, in the words of the option's converter (``> 0``), or ''."""
    convert = action.type
    if convert is None or action.choices is not None or action.nargs == 0:
        return ""
    for probe in _PROBES:
        try:
            convert(probe)
        except argparse.ArgumentTypeError as exc:
            message = str(exc)
            message = message.split(": ", 1)[1] if ": " in message else message
            return message.removeprefix("must be ")
        except Exception:  # noqa: BLE001 -- a plain type (float, Path): no stated domain
            return ""
    return ""


def _default(action: argparse.Action) -> str:
    """The default for the table: ``required``, the value, or empty."""
    if action.required:
        return "required"
    default = action.default
    if default is None or default is argparse.SUPPRESS or action.nargs == 0:
        return ""
    if isinstance(default, (list, tuple)):
        default = " ".join(str(v) for v in default)
    return _code(default)


def _help(action: argparse.Action, prog: str) -> str:
    """The option's help with argparse's ``%(default)s``-style fields filled in."""
    text = action.help or ""
    if "%" in text:
        params = {k: v for k, v in vars(action).items() if v is not argparse.SUPPRESS}
        params["prog"] = prog
        for key in ("choices",):
            if params.get(key) is not None:
                params[key] = ", ".join(str(c) for c in params[key])
        try:
            text = text % params
        except (KeyError, TypeError, ValueError):
            pass
    return text


def _shown(action: argparse.Action) -> bool:
    return action.help is not argparse.SUPPRESS and not isinstance(
        action, (argparse._HelpAction, argparse._SubParsersAction))


def _usage(parser: argparse.ArgumentParser) -> str:
    """One usage line: required options, ``[options]``, then the positionals."""
    words = [parser.prog]
    optional = False
    for action in parser._actions:
        if not _shown(action) or not action.option_strings:
            continue
        if action.required:
            value = _metavar(action, False)
            words.append(f"{action.option_strings[-1]} {value}".strip())
        else:
            optional = True
    if optional:
        words.append("[options]")
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            words.append("COMMAND ...")
        elif _shown(action) and not action.option_strings:
            words.append(_metavar(action, True))
    return " ".join(words)


def _table(actions, prog: str, deprecated=None) -> list[str]:
    deprecated = deprecated or {}
    rows = ["| option | value | default | meaning |", "|---|---|---|---|"]
    for action in actions:
        positional = not action.option_strings
        old = [o for o in action.option_strings if o in deprecated]
        name = action.dest if positional else ", ".join(
            o for o in action.option_strings if o not in deprecated)
        value = "" if positional else _metavar(action, positional)
        cells = [_code(name), _code(value) if value else "", _default(action), ""]
        domain = _domain(action)
        if domain:
            cells[1] += f" ({_escape(domain)})" if cells[1] else _escape(domain)
        if action.nargs == argparse.OPTIONAL and action.option_strings and \
                action.const is not None:
            cells[1] += f"; alone: {_code(action.const)}"
        meaning = _help(action, prog)
        if isinstance(action, argparse._VersionAction):
            meaning = meaning or "print the version and exit"
        if old:
            meaning += f" (deprecated spelling, still accepted: {', '.join(old)})"
        cells[3] = _escape(meaning)
        rows.append("| " + " | ".join(cells) + " |")
    return rows


def _groups(parser: argparse.ArgumentParser):
    """(title, actions) of every argument group with options to show, in parser order."""
    for group in parser._action_groups:
        actions = [a for a in group._group_actions if _shown(a)]
        if actions:
            yield group.title, group.description, actions


def _subcommands(parser: argparse.ArgumentParser):
    """(name, one-line help, parser) of every subcommand, in the order they were added."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                yield name, helps.get(name), sub


def _command(name: str, summary: str | None, parser: argparse.ArgumentParser,
             level: int) -> list[str]:
    out = [f"{'#' * level} `{parser.prog}`", ""]
    for text in (summary, parser.description):
        if text:
            text = text[0].upper() + text[1:]
            out += [_escape(text if text.endswith(".") else text + "."), ""]
    out += ["```text", _usage(parser), "```", ""]
    groups = list(_groups(parser))
    # argparse's own groups (positionals, options) form the command's first table
    main = [a for title, _, actions in groups if title in _DEFAULT_TITLES for a in actions]
    old = parser.get_default("_deprecated") or {}
    if main:
        out += _table(main, parser.prog, old) + [""]
    for title, description, actions in groups:
        if title not in _DEFAULT_TITLES:
            heading = "#" * (level + 1)
            if title.startswith("-"):  # a group named after an option value
                text = f"Options of {_code(title)}"
            elif title.lower().startswith("option"):
                text = _escape(title[0].upper() + title[1:])
            else:
                text = f"Options: {_escape(title)}"
            out += [f"{heading} {text}", ""]
            if description:
                out += [_escape(description), ""]
            out += _table(actions, parser.prog, old) + [""]
    for sub_name, sub_summary, sub in _subcommands(parser):
        out += _command(sub_name, sub_summary, sub, level + 1)
    return out


def cli_reference(parser: argparse.ArgumentParser | None = None) -> str:
    """Markdown reference of every command and option of `parser`.

    Parameters
    ----------
    parser : argparse.ArgumentParser, optional
        The parser to document; default the ``lidarstat`` command's
        (:func:`lidarstat.cli._app.build_parser`).

    Returns
    -------
    str
        The page: a header, the global options, then one section per command with its
        description, usage line and a table of its options per argument group.

    Examples
    --------
    >>> text = cli_reference()
    >>> text.splitlines()[0]
    '# Command-line reference'
    >>> "## `lidarstat curvature`" in text
    True
    """
    if parser is None:
        from ._app import build_parser

        parser = build_parser()
    out = [_HEADER.format(regenerate=REGENERATE)]
    out += ["## Global options", "", "```text", _usage(parser), "```", ""]
    options = [a for title, _, actions in _groups(parser) if title != "positional arguments"
               for a in actions]
    out += _table(options, parser.prog) + [""]
    commands = list(_subcommands(parser))
    out += ["| command | what it does |", "|---|---|"]
    out += [f"| [{_code(name)}](#lidarstat-{name}) | {_escape(summary or '')} |"
            for name, summary, _ in commands]
    out.append("")
    for name, summary, sub in commands:
        out += _command(name, summary, sub, 2)
    return "\n".join(out).rstrip("\n") + "\n"


def main(argv=None) -> int:
    """``python -m lidarstat.cli._reference [PATH]``: write the reference (default stdout).

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (default ``sys.argv[1:]``): at most one output path.

    Returns
    -------
    int
        Exit status: 0 written, 2 usage error.
    """
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) > 1 or (argv and argv[0].startswith("-")):
        print(f"usage: {REGENERATE.replace('docs/cli.md', '[PATH]')}", file=sys.stderr)
        return 2
    text = cli_reference()
    if argv:
        Path(argv[0]).write_text(text, encoding="utf-8")
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
