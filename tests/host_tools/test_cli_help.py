"""What a new user reads first: every verb's --help and the synopses in docs/ agree with the parsers.

- a doc synopsis (a code-block line `propid VERB ...` with its continuation lines, holding a `[--option`)
  names every option of VERB, and any `propid VERB --option` in docs/ and README.md names one that exists;
- an option whose default is a value says it in its help;
- --help wraps only at spaces: an option named in a help text and a default comma list stay whole;
- every verb that draws a progress bar takes --no-progress.
"""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path

import pytest

from propid.cli import build_parser

REPO = Path(__file__).resolve().parents[2]
DOCS = sorted((REPO / "docs").glob("*.md")) + [REPO / "README.md"]
# replay's synopsis ends with `[--<any propid_config_t field> X]`: the options of this group
CONFIG_GROUP = "filter configuration overrides (propid_config_t fields)"


def _verbs() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


VERBS = _verbs()


def _options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in parser._actions if a.option_strings and not isinstance(a, argparse._HelpAction)]


def _doc_commands():
    """(file, line, verb, text, is_synopsis) of every `propid VERB` line in a code block, with its
    continuation lines (a trailing backslash, or indented lines that do not start another command)."""
    for path in DOCS:
        lines = path.read_text().splitlines()
        in_block, i = False, 0
        while i < len(lines):
            line = lines[i]
            if line.startswith("```"):
                in_block = not in_block
            else:
                match = re.match(r"\s*propid ([a-z0-9-]+)\b", line) if in_block else None
                if match and match.group(1) in VERBS:
                    text, j = line, i
                    while j + 1 < len(lines) and (text.rstrip().endswith("\\") or (
                            lines[j + 1].startswith("    ") and not lines[j + 1].strip().startswith("propid "))):
                        j += 1
                        text += " " + lines[j]
                    yield path.name, i + 1, match.group(1), text, "[--" in text
                    i = j
            i += 1


def test_doc_synopses_name_every_option():
    synopses = [(f, n, verb, text) for f, n, verb, text, is_synopsis in _doc_commands() if is_synopsis]
    assert {verb for _, _, verb, _ in synopses} >= {"convert", "replay", "gap", "listen", "log", "plot",
                                                   "bound-check"}
    missing = []
    for name, line, verb, text in synopses:
        named = set(re.findall(r"--[a-z0-9][a-z0-9-]*", text))
        for action in _options(VERBS[verb]):
            group = next((g.title for g in VERBS[verb]._action_groups if action in g._group_actions), "")
            if "--<any propid_config_t field>" in text and group == CONFIG_GROUP:
                continue
            if not named & set(action.option_strings):
                missing.append(f"{name}:{line} {verb} {action.option_strings[0]}")
    assert not missing, missing


def test_docs_name_only_options_that_exist():
    unknown = []
    for name, line, verb, text, _ in _doc_commands():
        known = {o for a in VERBS[verb]._actions for o in a.option_strings}
        unknown += [f"{name}:{line} {verb} {o}" for o in re.findall(r"--[a-z0-9][a-z0-9-]*", text) if o not in known]
    for path in DOCS:
        for number, line in enumerate(path.read_text().splitlines(), start=1):
            for match in re.finditer(r"`propid ([a-z0-9-]+)([^`]*)`", line):
                if match.group(1) in VERBS:
                    known = {o for a in VERBS[match.group(1)]._actions for o in a.option_strings}
                    unknown += [f"{path.name}:{number} {match.group(1)} {o}"
                                for o in re.findall(r"--[a-z0-9][a-z0-9-]*", match.group(2)) if o not in known]
    assert not unknown, unknown


def test_every_default_value_is_in_the_help():
    silent = []
    for verb, parser in VERBS.items():
        for action in _options(parser):
            if action.default in (None, False, "", [], argparse.SUPPRESS) or action.help is None:
                continue
            if "default" not in action.help.lower():
                silent.append(f"{verb} {action.option_strings[0]} (default {action.default!r})")
    assert not silent, silent


@pytest.mark.parametrize("verb", sorted(VERBS))
def test_help_keeps_option_names_and_lists_whole(verb, monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    parser = VERBS[verb]
    lines = parser.format_help().splitlines()
    words = {w for line in lines for w in line.split()}
    for action in _options(parser):
        text = action.help % {"default": action.default} if "%(" in (action.help or "") else (action.help or "")
        for option in re.findall(r"--[a-z0-9][a-z0-9-]*[a-z0-9]", text):
            assert any(option in w for w in words), f"{verb}: {option} split across lines"
        if isinstance(action.default, str) and "," in action.default:
            for item in action.default.split(","):
                assert any(item in w.strip("(),:") for w in words), f"{verb} {action.option_strings[0]}: {item}"
    assert not any(line.rstrip().endswith(("--", "-")) for line in lines), verb


def test_every_verb_with_a_progress_bar_takes_no_progress():
    quiet = [verb for verb, parser in VERBS.items() if "--quiet" in parser._option_string_actions]
    assert quiet  # gap and log keep --quiet as the older spelling ...
    for verb in quiet:  # ... beside the spelling of every other verb
        action = VERBS[verb]._option_string_actions["--quiet"]
        assert "--no-progress" in action.option_strings, verb
        assert VERBS[verb].parse_args(["--no-progress"] + _required(verb)).quiet is True


def _required(verb: str) -> list[str]:
    return {"gap": ["--log", "a.csv"]}.get(verb, [])



def test_every_make_verb_of_make_help_is_in_the_readme_and_build_md():
    verbs = re.findall(r'@echo "  make ([a-z0-9-]+)', (REPO / "Makefile").read_text())
    assert {"sitl", "test", "gap-bench", "soak"} <= set(verbs)
    for doc in ("README.md", "docs/build.md"):
        text = (REPO / doc).read_text()
        assert not [v for v in verbs if f"`make {v}`" not in text], doc


@pytest.mark.parametrize("verb", ["listen", "table1", "campaign", "gap-bench", "replay"])
def test_an_unknown_option_is_named_by_its_verb(verb, capsys):
    """`propid VERB --bogus` ends with VERB's usage and "propid VERB: error" (it said "propid: error",
    with the top level's usage, for the verbs whose parser takes no required argument)."""
    from propid.cli import main
    with pytest.raises(SystemExit) as exc:
        main([verb, "--log", "x.csv", "--bogus"] if verb == "replay" else [verb, "--bogus"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"usage: propid {verb}" in err
    assert err.strip().splitlines()[-1] == f"propid {verb}: error: unrecognized arguments: --bogus"
