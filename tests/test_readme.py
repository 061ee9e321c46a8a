"""The README works when copied: its Python runs, its `kinema ...` commands parse with the real command
line, the commands of "Generate a motion" run, every file a `kinema render` line reads is one an earlier
command wrote, the generate options it names exist, and the example files it names exist."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
import torch

import kinema
from kinema.cli import build_parser, main

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
TEXT = README.read_text()


def fenced(text: str, lang: str) -> list[str]:
    """The contents of the ```lang blocks of a Markdown text."""
    return re.findall(rf"^```{lang}[ \t]*\n(.*?)^```", text, flags=re.M | re.S)


def shell_lines(block: str) -> list[str]:
    """The commands of a shell block: continuation lines (ending in a backslash) joined, comments and
    blank lines dropped."""
    out, current = [], ""
    for line in block.splitlines():
        if line.rstrip().endswith("\\"):
            current += line.rstrip()[:-1] + " "
            continue
        current += line
        tokens = shlex.split(current, comments=True)
        if tokens:
            out.append(shlex.join(tokens))
        current = ""
    assert not current.strip(), f"a shell block ends in a continuation line: {current!r}"
    return out


def kinema_commands(text: str) -> list[str]:
    """Every `kinema ...` command: in bash blocks, and inline in the prose (`kinema render x --out y`)."""
    cmds = [c for block in fenced(text, "bash") for c in shell_lines(block) if c.split()[0] == "kinema"]
    cmds += [c for c in re.findall(r"`(kinema [^`]+)`", text) if "..." not in c]
    return cmds


def section(title: str) -> str:
    start = TEXT.index(f"\n## {title}\n")
    end = TEXT.find("\n## ", start + 1)
    return TEXT[start : end if end >= 0 else None]


COMMANDS = kinema_commands(TEXT)


def parse(command: str):
    try:
        return build_parser().parse_args(shlex.split(command)[1:])
    except SystemExit as err:  # argparse prints the reason on stderr
        pytest.fail(f"README command does not parse (exit {err.code}): {command}")


def test_readme_has_commands_and_python():
    assert len(COMMANDS) >= 10
    assert fenced(TEXT, "python")


@pytest.mark.parametrize("command", COMMANDS)
def test_command_parses(command):
    parse(command)


def test_rendered_files_were_written_first():
    """`kinema render FILE` reads a file that an earlier command of the README wrote (its --out or
    convert's output), so that the commands can be run in order."""
    written = set()
    for command in COMMANDS:
        args = parse(command)
        if args.command == "render":
            assert str(args.motion) in written, f"{command}: nothing above writes {args.motion}"
        if getattr(args, "out", None) is not None:
            written.add(str(args.out))
        if args.command == "convert":
            written.add(str(args.output))


def test_generate_options_exist():
    """The options the README lists for `kinema generate` (its "Options:" paragraph) are real."""
    parser = build_parser()
    generate = next(a for a in parser._actions if a.dest == "command").choices["generate"]
    known = set(generate._option_string_actions)
    paragraph = TEXT[TEXT.index("Options: `--constraints") : TEXT.index("```python")]
    named = set(re.findall(r"`(--[a-z][a-z-]*)", paragraph))
    assert len(named) >= 8
    assert named <= known, f"README names options that `kinema generate` lacks: {sorted(named - known)}"


def test_named_example_files_exist():
    names = set(re.findall(r"`(?:python )?(examples/[^`\s]*)`", TEXT))
    assert names
    for name in names:
        assert (REPO / name).exists(), f"README names {name}, which does not exist"


def test_python_snippets_run(tmp_path, monkeypatch, capsys):
    """Each ```python block, run as a script from a folder that has the repository's examples/ (as when
    it is run from the repository root); every file it saves exists and holds a finite motion."""
    (tmp_path / "examples").symlink_to(REPO / "examples", target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    for i, block in enumerate(fenced(TEXT, "python")):
        exec(compile(block, f"README.md python block {i}", "exec"), {"__name__": "__main__"})
        saved = re.findall(r"\.save\(\s*[\"']([^\"']+)[\"']", block)
        assert saved, f"python block {i} saves no file"
        for name in saved:
            motion = kinema.load_motion(tmp_path / name)
            assert motion.is_finite() and torch.isfinite(motion.positions).all()
    out = capsys.readouterr().out
    print(out)
    assert "[]" in out  # the snippet prints result.report.warnings: none for the shipped example


def test_generate_section_runs(tmp_path, monkeypatch):
    """The commands of "Generate a motion" run as written, in order, in an empty folder."""
    monkeypatch.chdir(tmp_path)
    commands = kinema_commands(section("Generate a motion"))
    assert [c.split()[1] for c in commands] == ["generate", "render"]
    for command in commands:
        argv = shlex.split(command)[1:]
        if argv[0] == "generate":
            argv.append("--no-progress")
        assert main(argv) == 0, command
        out = parse(command).out
        assert (tmp_path / out).is_file(), f"{command} wrote no {out}"
