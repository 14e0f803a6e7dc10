"""mkdocs hooks of the site (mkdocs.yml's ``hooks``), run at every build, never a solve.

* The command line's page is written from the parser itself
  (:func:`casadi_keyframe.cli.build_parser`): each ``<!-- cli: COMMAND -->`` marker becomes
  that command's ``--help`` and ``<!-- cli: commands -->`` the list of commands, so the page
  cannot drift from the command.
* The docstrings are written for ``help()`` and Sphinx roles (``:func:`~a.b```); on the
  page a role's name stays, in code, without the role.
"""
from __future__ import annotations

import argparse
import os
import re

MARKER = re.compile(r"<!-- cli: ([\w-]+) -->")
ROLE = re.compile(r":(?:func|class|meth|mod|attr|data|exc|obj):<code>(~?)([^<]*)</code>")


def _commands() -> tuple[argparse.ArgumentParser, argparse._SubParsersAction]:
    from casadi_keyframe.cli import build_parser

    parser = build_parser()
    return parser, next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


def _help(name: str, parser, sub) -> str:
    if name == "commands":
        rows = [f"| [`{a.dest}`](#{a.dest}) | {a.help} |" for a in sub._choices_actions]
        return "| command | what it does |\n|---|---|\n" + "\n".join(rows)
    if name != "casadi-keyframe" and name not in sub.choices:
        raise KeyError(f"docs: <!-- cli: {name} --> names no command of casadi-keyframe; "
                       f"the commands are {', '.join(sub.choices)}")
    command = parser if name == "casadi-keyframe" else sub.choices[name]
    return "```text\n" + command.format_help().rstrip() + "\n```"


def on_page_markdown(markdown, page, config, files):
    if not MARKER.search(markdown):
        return markdown
    os.environ["COLUMNS"] = "90"  # argparse wraps at the terminal's width: one width here
    parser, sub = _commands()
    missing = [n for n in sub.choices if "commands" in MARKER.findall(markdown)
               and n not in MARKER.findall(markdown)]
    if missing:
        raise ValueError(f"docs: {page.file.src_path} has no <!-- cli: NAME --> for the "
                         f"commands {', '.join(missing)}")
    return MARKER.sub(lambda m: _help(m.group(1), parser, sub), markdown)


def _short(match: re.Match) -> str:
    tilde, name = match.groups()
    return f"<code>{name.rsplit('.', 1)[-1] if tilde else name}</code>"


def on_page_content(html, page, config, files):
    return ROLE.sub(_short, html)
