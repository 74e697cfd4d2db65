"""The README is a user's document: short, free of working-log words, and every command,
option, file and link it shows exists."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from ehm_drake.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
#: Folders of the repository a README path may start with.
REPO_ROOTS = ("ehm_drake/", "docs/", "tests/", "bench/", "sdf/", "notebooks/", ".ci/")
#: Words of a working log: which session, which registered run, the brief.
LOG_WORDS = (r"\bstops? \d+", r"\bthe brief\b", r"\bs\d{4}\b", r"\bseed \d{4}\b",
             r"\bregistered (?:runs?|before)\b", r"\bissue \"", r"\bcommit [0-9a-f]{7}")


def test_the_readme_is_short_and_free_of_working_log_words():
    assert len(README.splitlines()) <= 400
    for pattern in LOG_WORDS:
        hits = re.findall(pattern, README, flags=re.IGNORECASE)
        assert not hits, (pattern, hits[:3])


def _subcommands() -> dict:
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return action.choices


def _command_lines(text: str):
    """Every `ehm-drake ...` command of the README with its continuation lines (a usage
    block line that starts with spaces continues the command above it)."""
    current = None
    for line in text.splitlines():
        s = line.strip()
        stripped = s.strip("`*")
        if "ehm-drake " in line:
            if current:
                yield current
            current = line[line.index("ehm-drake "):].split("#")[0]
            if "`" in current:  # inline: up to the closing backquote
                current = current.split("`")[0]
            if current.rstrip().endswith(","):
                current = current.rstrip(", ")
        elif current and line.startswith("  ") and stripped.startswith("["):
            current += " " + s
        else:
            if current:
                yield current
            current = None
    if current:
        yield current


def test_every_command_and_option_the_readme_shows_exists():
    subs = _subcommands()
    lines = list(_command_lines(README))
    assert len(lines) >= 15
    seen = set()
    for cmd in lines:
        words = cmd.split()
        name = words[1]
        assert name in subs, cmd
        options = subs[name]._option_string_actions
        for opt in re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", cmd):
            assert opt in options, (name, opt)
        seen.add(name)
    # Every subcommand is shown.
    assert seen == set(subs), set(subs) - seen


@pytest.mark.parametrize("script", sorted({m for m in re.findall(r"python (bench/\w+\.py)",
                                                                  README)}))
def test_every_benchmark_the_readme_runs_takes_its_options(script):
    options = set()
    for m in re.finditer(rf"python {re.escape(script)}([^`|]*)", README):
        options |= set(re.findall(r"--[a-z][a-z0-9-]*", m.group(1)))
    out = subprocess.run([sys.executable, str(ROOT / script), "--help"], capture_output=True,
                         text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-500:]
    for opt in options:
        assert opt in out.stdout, (script, opt)


def test_every_file_and_link_the_readme_names_exists():
    links = re.findall(r"\]\(([^)\s]+)\)", README)
    paths = [p for p in links if not re.match(r"[a-z]+://", p)]
    paths += [p for p in re.findall(r"`([^`\s]+)`", README) if p.startswith(REPO_ROOTS)]
    paths += re.findall(r"^(?:sdf|ehm_drake|bench|docs|notebooks|tests)/[\w./]*", README,
                        flags=re.MULTILINE)
    assert len(paths) >= 20
    missing = sorted({p for p in paths if not (ROOT / p.split("#")[0]).exists()})
    assert not missing


def test_the_python_example_runs_and_gives_a_vertical_apparent_mass():
    block = re.search(r"```python\n(.*?)```", README, flags=re.DOTALL).group(1)
    scope: dict = {}
    exec(compile(block, "README.md", "exec"), scope)
    # At 1 m/s^2 the apparent mass rises from about 1 at 2 Hz to its 4-6 Hz resonance.
    modulus = scope["modulus"]
    assert 0.9 < modulus[0] < 1.1 and modulus[1] > 1.1 and modulus[2] > 1.1


def _user_facing_files():
    """What users read besides the README: the package (docstrings, help, report texts),
    the benchmarks, the notebooks and the documentation outside its history."""
    for folder, pattern in (("ehm_drake", "*.py"), ("bench", "*.py"), ("notebooks", "*.ipynb"),
                            ("docs", "*.md")):
        for p in sorted((ROOT / folder).rglob(pattern)):
            rel = p.relative_to(ROOT).as_posix()
            if not rel.startswith(("docs/history/", "docs/_build/", "docs/tutorials/")):
                yield rel, p.read_text()


def test_working_log_words_live_only_in_the_history():
    """Which session, which seed of which run: docs/history, dated; never where a user
    reads how the tool works."""
    hits = [(rel, m.group(0)) for rel, text in _user_facing_files() for pattern in LOG_WORDS
            for m in re.finditer(pattern, text, flags=re.IGNORECASE)]
    assert not hits, hits[:10]
