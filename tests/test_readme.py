"""The README is the front door: short, its example runs, its command table is the CLI, its links lead somewhere."""

import re
from pathlib import Path

import click
import numpy as np

from wardjax.run import main

ROOT = Path(__file__).parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_readme_is_short():
    assert len(README.splitlines()) <= 100


def test_readme_python_example_runs_and_recovers_the_truth():
    blocks = re.findall(r"```python\n(.*?)```", README, re.S)
    assert len(blocks) == 1 and len(blocks[0].strip().splitlines()) <= 12
    ns: dict = {}
    exec(compile(blocks[0], "README.md", "exec"), ns)  # the README's own example
    truth, joint = ns["truth"], ns["joint"]
    for name in ("rho_s", "alpha_x", "alpha_y"):  # the joint fit finds the simulated material within 4 σ
        fitted, err = float(getattr(joint.params, name)), float(getattr(joint.stderr, name))
        assert abs(fitted - float(getattr(truth, name))) < 4 * err, name
    assert np.all(np.isfinite(ns["texture"]))


def _commands(group: click.Group, prefix: str = "wardjax") -> list[str]:
    out = []
    for name, cmd in sorted(group.commands.items()):
        if isinstance(cmd, click.Group):
            out += _commands(cmd, f"{prefix} {name}")
        else:
            out.append(f"{prefix} {name}")
    return out


def test_readme_command_table_has_one_line_per_command():
    rows = [m.group(1) for m in re.finditer(r"^\| `(wardjax [^`]*)` \|", README, re.M)]
    commands = _commands(main)
    assert len(commands) >= 8  # demo, fit, simulate, texture analyze/synthesize, gratings, diagnose, report
    for command in commands:
        assert sum(row.startswith(command + " ") or row == command for row in rows) == 1, command
    assert len(rows) == len(commands)
    assert "(docs/cli.md)" in README


def test_readme_names_only_files_in_the_repository():
    # every link, and every backticked path under a folder of the repository, names a file that is there
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", README)
    assert links
    for target in links:
        assert not target.startswith("http"), target
        assert (ROOT / target).exists(), target
    top = {p.name for p in ROOT.iterdir() if p.name not in {".git", ".venv"}}
    for token in re.findall(r"`([^` ]+)`", README):
        head = token.split("/")[0]
        if "/" in token and head in top:
            assert (ROOT / token.rstrip("/")).exists(), token
    # the docs pages the README points into are pages of the site
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    for target in links:
        if target.startswith("docs/") and target.endswith(".md"):
            assert target.removeprefix("docs/") in nav, target
