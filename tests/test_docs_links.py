"""The documentation as a reader meets it (issue 31): README.md, docs/**/*.md and deploy/README.md.

- every relative link and image resolves to a file of the checkout, and every ``#anchor`` to a
  heading (GitHub's anchors) or an explicit anchor of the page it points into;
- every ``egc-teleop SUBCOMMAND ...`` command line in a ``sh``/``bash``/``shell``/``console``
  block (and every ``make demo DEMO_ARGS=...``) parses with the real argument parsers
  (``python -m egc_app.parse_check``: the parsers without running anything, and the checks a
  subcommand makes of its arguments alone, such as ``--goal`` without ``--robot``; DESIGN 2:
  nothing imports ``egc_app``);
- docs/cli.md has a section for every subcommand of ``egc_app/cli.py`` and names every one of
  its flags there, as ``egc-teleop NAME --help`` lists them;
- the index (docs/README.md) reaches every page under docs/, directly or through pages it links;
- README.md stays a newcomer's page: at most 250 lines;
- docs/benchmarks.md is what ``egc-teleop bench report`` renders from bench/results/.
"""

from __future__ import annotations

import ast
import json
import re
import shlex
import subprocess
import sys
import urllib.parse
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests import cli_process

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
INDEX = DOCS / "README.md"
CLI_PAGE = DOCS / "cli.md"
PAGES = sorted({ROOT / "README.md", ROOT / "deploy" / "README.md", *DOCS.rglob("*.md")})
COMMAND_LANGUAGES = {"sh", "bash", "shell", "console"}
README_MAX_LINES = 250

FENCE = re.compile(r"^\s*(?P<fence>`{3,}|~{3,})(?P<info>[^`]*)$")
HEADING = re.compile(r"^ {0,3}(#{1,6})[ \t]+(.*?)[ \t]*#*[ \t]*$")
INLINE_LINK = re.compile(
    r"!?\[(?P<text>(?:[^\[\]]|\[[^\]]*\])*)\]\((?P<target>[^()\s]*(?:\([^()]*\)[^()\s]*)*)(?:\s+\"[^\"]*\")?\)"
)
REFERENCE_DEF = re.compile(r"^ {0,3}\[[^\]]+\]:\s+(\S+)", re.M)
HTML_LINK = re.compile(r"<(?:a|img)\b[^>]*?\b(?:href|src)=\"([^\"]+)\"", re.I)
HTML_ANCHOR = re.compile(r"<a\b[^>]*?\b(?:name|id)=\"([^\"]+)\"", re.I)
CODE_SPAN = re.compile(r"(`+)(.+?)\1")


@dataclass(frozen=True)
class Line:
    number: int
    text: str


@dataclass(frozen=True)
class Block:
    language: str
    lines: tuple[Line, ...]


def split_page(text: str) -> tuple[list[Line], list[Block]]:
    """The page's prose lines (outside fenced code) and its fenced blocks (a fence may be
    indented, inside a list item)."""
    prose: list[Line] = []
    blocks: list[Block] = []
    fence: str | None = None
    language = ""
    body: list[Line] = []
    for number, raw in enumerate(text.splitlines(), 1):
        match = FENCE.match(raw)
        if fence is None:
            if match:
                fence = match["fence"]
                language = (match["info"].split() or [""])[0].lower()
            else:
                prose.append(Line(number, raw))
        elif match and match["fence"].startswith(fence) and not match["info"].strip():
            blocks.append(Block(language, tuple(body)))
            fence, body = None, []
        else:
            body.append(Line(number, raw))
    assert fence is None, "a fenced block is never closed"
    return prose, blocks


def without_code_spans(text: str) -> str:
    return CODE_SPAN.sub(lambda m: " " * len(m.group(0)), text)


def github_anchor(heading: str) -> str:
    """GitHub's anchor for a heading's text: the rendered text lowercased, punctuation but
    hyphens and underscores dropped, spaces to hyphens."""
    text = INLINE_LINK.sub(lambda m: m["text"], heading)
    text = re.sub(r"<[^>]+>", "", text)
    text = text.replace("`", "")
    text = re.sub(r"(\*\*|__|\*)(.+?)\1", r"\2", text)
    kept = "".join(c for c in text.strip().lower() if c.isalnum() or c in " -_")
    return kept.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    prose, _ = split_page(page.read_text(encoding="utf-8"))
    found: set[str] = set()
    seen: dict[str, int] = {}
    for line in prose:
        found.update(HTML_ANCHOR.findall(line.text))
        match = HEADING.match(line.text)
        if match is None:
            continue
        base = github_anchor(match.group(2))
        count = seen.get(base, 0)
        seen[base] = count + 1
        found.add(base if count == 0 else f"{base}-{count}")
    return found


def paragraphs(lines: list[Line]) -> Iterator[Line]:
    """Consecutive prose lines joined (a link's text may wrap), each with its first line."""
    group: list[Line] = []
    for line in [*lines, Line(0, "")]:
        if line.text.strip() and (not group or line.number == group[-1].number + 1):
            group.append(line)
            continue
        if group:
            yield Line(group[0].number, "\n".join(g.text for g in group))
        group = [line] if line.text.strip() else []


def links(page: Path) -> Iterator[tuple[int, str]]:
    """(line, target) of every link and image on the page, outside code."""
    prose, _ = split_page(page.read_text(encoding="utf-8"))
    for para in paragraphs(prose):
        text = without_code_spans(para.text)
        found = [(m.start(), m["target"].strip("<>")) for m in INLINE_LINK.finditer(text)]
        found += [(m.start(), m.group(1).strip("<>")) for m in REFERENCE_DEF.finditer(text)]
        found += [(m.start(), m.group(1)) for m in HTML_LINK.finditer(text)]
        for offset, target in sorted(found):
            yield para.number + text.count("\n", 0, offset), target


def is_external(target: str) -> bool:
    return bool(re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I))


def resolve(page: Path, target: str) -> tuple[Path, str]:
    path, _, fragment = target.partition("#")
    file = (page.parent / urllib.parse.unquote(path)).resolve() if path else page
    return file, urllib.parse.unquote(fragment)


def rel(path: Path) -> str:
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


# ---------------------------------------------------------------------------------------------
# Links and anchors


def test_the_page_list_is_what_a_reader_gets():
    assert INDEX in PAGES and CLI_PAGE in PAGES and len(PAGES) > 20


def test_the_anchor_rule_is_githubs():
    assert github_anchor("`egc-teleop robot` and `egc-teleop operator`") == (
        "egc-teleop-robot-and-egc-teleop-operator"
    )
    assert github_anchor("States and safety (DESIGN 8)") == "states-and-safety-design-8"
    assert github_anchor("Sites, TLS and who may drive what") == "sites-tls-and-who-may-drive-what"
    assert github_anchor("`[dwa]`") == "dwa"
    assert github_anchor("[A link](x.md) in a heading") == "a-link-in-a-heading"
    assert github_anchor("Start order, and a router that is down") == (
        "start-order-and-a-router-that-is-down"
    )


def test_the_scanner_sees_links_and_skips_code(tmp_path):
    page = tmp_path / "p.md"
    page.write_text(
        "# Top\n\n[a](b.md#c) and ![img](d.png) but `[not](x.md)`\n\n```sh\n[no](y.md)\n```\n"
        "\n1. a list\n   ```sh\n   [no](z.md)\n   ```\n\n[ref]: e.md\n## Top\n",
        encoding="utf-8",
    )
    assert [t for _, t in links(page)] == ["b.md#c", "d.png", "e.md"]
    assert anchors(page) == {"top", "top-1"}


@pytest.mark.parametrize("page", PAGES, ids=rel)
def test_every_relative_link_resolves(page):
    problems = []
    for number, target in links(page):
        if not target or is_external(target):
            continue
        file, fragment = resolve(page, target)
        where = f"{rel(page)}:{number}: {target}"
        if not file.exists():
            problems.append(f"{where}: no such file {rel(file)}")
        elif not file.is_relative_to(ROOT):
            problems.append(f"{where}: outside the checkout")
        elif fragment and file.suffix == ".md" and fragment not in anchors(file):
            problems.append(f"{where}: no heading or anchor #{fragment} in {rel(file)}")
    assert not problems, "broken links:\n" + "\n".join(problems)


def test_the_index_reaches_every_docs_page():
    reached = {INDEX}
    todo = [INDEX]
    while todo:
        page = todo.pop()
        for _, target in links(page):
            if is_external(target):
                continue
            file, _ = resolve(page, target)
            if (
                file.suffix == ".md"
                and file.is_file()
                and file.is_relative_to(ROOT)
                and file not in reached
            ):
                reached.add(file)
                todo.append(file)
    missing = sorted(rel(p) for p in DOCS.rglob("*.md") if p not in reached)
    assert not missing, f"docs pages the index does not reach: {missing}"


def test_the_readme_is_a_newcomers_page():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, (
        f"README.md has {len(lines)} lines (at most {README_MAX_LINES})"
    )
    text = "\n".join(lines)
    for must in ("make demo", "make test", "docs/README.md"):
        assert must in text, must


# ---------------------------------------------------------------------------------------------
# Command lines in the pages


def command_lines(block: Block) -> Iterator[tuple[int, str]]:
    """The block's shell command lines, continuations joined; ``console`` blocks only the lines
    after a ``$`` prompt."""
    pending: list[str] = []
    start = 0
    for line in block.lines:
        text = line.text
        if not pending:
            start = line.number
            if block.language == "console":
                if not text.lstrip().startswith("$ "):
                    continue
                text = text.lstrip()[2:]
        if text.rstrip().endswith("\\"):
            pending.append(text.rstrip()[:-1])
            continue
        pending.append(text)
        yield start, " ".join(part.strip() for part in pending)
        pending = []
    if pending:
        yield start, " ".join(part.strip() for part in pending)


SEPARATORS = {"|", "||", "&", "&&", ";", "(", ")"}
REDIRECTS = re.compile(r"^\d*[<>]+&?$")


def simple_commands(line: str) -> Iterator[list[str]]:
    """The words of each simple command on a shell line (pipes, lists and redirections taken
    apart, comments dropped)."""
    lexer = shlex.shlex(line, posix=True, punctuation_chars=";&|<>()")
    lexer.whitespace_split = True
    lexer.commenters = "#"
    words: list[str] = []
    skip_next = False
    for token in lexer:
        if skip_next:
            skip_next = False
            continue
        if token in SEPARATORS:
            if words:
                yield words
            words = []
        elif REDIRECTS.match(token):
            skip_next = True
        else:
            words.append(token)
    if words:
        yield words


def egc_teleop_argv(words: list[str]) -> list[str] | None:
    """The words after ``egc-teleop`` (any path to it, after ``VAR=x`` assignments), or those
    ``make demo DEMO_ARGS=...`` hands to ``egc-teleop demo``; None for other commands."""
    while words and re.match(r"^[A-Za-z_][A-Za-z0-9_]*=", words[0]):
        words = words[1:]
    if not words:
        return None
    if Path(words[0]).name == "egc-teleop":
        return words[1:]
    if words[0] == "make" and len(words) > 1 and words[1] in ("demo", "demo-ros2"):
        extra = [w.partition("=")[2] for w in words[2:] if w.startswith("DEMO_ARGS=")]
        ros2 = ["--ros2"] if words[1] == "demo-ros2" else []
        return ["demo", *ros2, *(shlex.split(extra[0]) if extra else [])]
    return None


def documented_commands() -> list[tuple[str, list[str]]]:
    found = []
    for page in PAGES:
        _, blocks = split_page(page.read_text(encoding="utf-8"))
        for block in blocks:
            if block.language not in COMMAND_LANGUAGES:
                continue
            for number, line in command_lines(block):
                for words in simple_commands(line):
                    argv = egc_teleop_argv(words)
                    if argv is not None:
                        found.append((f"{rel(page)}:{number}", argv))
    return found


def parse_check(argvs: list[list[str]]) -> list[dict]:
    proc = subprocess.run(
        [sys.executable, "-m", "egc_app.parse_check"],
        input="".join(json.dumps(a) + "\n" for a in argvs),
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr
    results = [json.loads(line) for line in proc.stdout.splitlines() if line.strip()]
    assert len(results) == len(argvs), proc.stderr
    return results


def test_the_command_line_scanner():
    block = Block(
        "sh",
        (
            Line(1, "egc-teleop robot --driver sim &   # the robot"),
            Line(2, "echo '{\"v\": 0.1}' | .venv/bin/egc-teleop filter --profile jackal"),
            Line(3, "egc-teleop episode --start -1,2,0 \\"),
            Line(4, "    --goal 3,4 --json > out.json"),
            Line(5, 'make demo DEMO_ARGS="--duration 20 --save demo.rrd"'),
            Line(6, "export ROS_DOMAIN_ID=57 && ROS_DOMAIN_ID=1 egc-teleop sim --ros2"),
        ),
    )
    argvs = [egc_teleop_argv(w) for _, line in command_lines(block) for w in simple_commands(line)]
    assert [a for a in argvs if a is not None] == [
        ["robot", "--driver", "sim"],
        ["filter", "--profile", "jackal"],
        ["episode", "--start", "-1,2,0", "--goal", "3,4", "--json"],
        ["demo", "--duration", "20", "--save", "demo.rrd"],
        ["sim", "--ros2"],
    ]


def test_the_parse_check_refuses_what_a_parser_refuses():
    """The check can fail: a flag no parser has, a bad choice, an unknown subcommand, and
    arguments the subcommand refuses together before it runs (via points without ``--robot``)."""
    results = parse_check(
        [
            ["robot", "--no-such-flag"],
            ["robot", "--driver", "carrier-pigeon"],
            ["teleport"],
            ["operator", "--script", "demo", "--goal", "8,1.2"],
            ["robot"],
            ["operator", "--robot", "sim", "--script", "demo", "--goal", "8,1.2"],
        ]
    )
    assert all("error" in r for r in results[:4]), results
    assert "--goal and --route need --robot" in results[3]["error"], results[3]
    assert results[4].get("command") == "robot", results[4]
    assert results[5].get("command") == "operator", results[5]


def test_every_documented_command_line_parses():
    commands = documented_commands()
    pages = {where.split(":")[0] for where, _ in commands}
    assert {"README.md", "docs/cli.md", "deploy/README.md"} <= pages, pages
    results = parse_check([argv for _, argv in commands])
    bad = [
        f"{where}: egc-teleop {shlex.join(argv)}\n    {result['error']}"
        for (where, argv), result in zip(commands, results, strict=True)
        if "error" in result
    ]
    assert not bad, "command lines that do not parse:\n" + "\n".join(bad)


# ---------------------------------------------------------------------------------------------
# The CLI reference covers every subcommand and flag


def subcommands() -> list[str]:
    """The keys of ``SUBCOMMANDS`` in egc_app/cli.py, read from its source (not imported)."""
    tree = ast.parse((ROOT / "egc_app" / "cli.py").read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.AnnAssign | ast.Assign):
            targets = [node.target] if isinstance(node, ast.AnnAssign) else node.targets
            if any(isinstance(t, ast.Name) and t.id == "SUBCOMMANDS" for t in targets):
                assert isinstance(node.value, ast.Dict)
                return [k.value for k in node.value.keys if isinstance(k, ast.Constant)]
    raise AssertionError("egc_app/cli.py has no SUBCOMMANDS")


def flags_of(names: list[str]) -> dict[str, set[str]]:
    """Each subcommand's flags as its ``--help`` shows them (``egc-teleop NAME --help`` as the
    console script runs it, all in one process: ``tests.cli_process.run_many``)."""
    helps = cli_process.run_many([((name, "--help"), ROOT) for name in names], COLUMNS="200")
    flags = {}
    for name, shown in zip(names, helps, strict=True):
        assert shown.code == 0, shown.stderr
        found = set(re.findall(r"(?<![\w-])(--[a-z0-9][a-z0-9-]*)", shown.stdout))
        flags[name] = found - {"--help"}
    return flags


def sections(page: Path) -> dict[str, str]:
    """Each ``## `` section's text by its anchor."""
    out: dict[str, str] = {}
    current = ""
    for line in page.read_text(encoding="utf-8").splitlines():
        match = HEADING.match(line)
        if match and len(match.group(1)) == 2:
            current = github_anchor(match.group(2))
            out[current] = ""
        out[current] = out.get(current, "") + line + "\n"
    return out


def test_the_cli_reference_names_every_subcommand_and_flag():
    names = subcommands()
    assert {"robot", "operator", "demo", "bench", "replay"} <= set(names)
    flags = flags_of(names)
    assert "--driver" in flags["robot"] and "--joystick" in flags["operator"]
    by_anchor = sections(CLI_PAGE)
    missing = []
    for name in names:
        text = by_anchor.get(f"egc-teleop-{name}")
        if text is None:
            missing.append(f"no section '## egc-teleop {name}'")
            continue
        if "(#zenoh-options)" in text:
            text += by_anchor.get("zenoh-options", "")
        for flag in sorted(flags[name]):
            if not re.search(rf"(?<![\w-]){re.escape(flag)}(?![\w-])", text):
                missing.append(f"egc-teleop {name} {flag}")
    assert not missing, "docs/cli.md does not document:\n" + "\n".join(missing)


# ---------------------------------------------------------------------------------------------
# The benchmark page is generated


def test_the_benchmark_page_is_rendered_from_the_results():
    from egc_experiments.bench_report import page_text

    page = DOCS / "benchmarks.md"
    assert page.read_text(encoding="utf-8") == page_text(), (
        "docs/benchmarks.md is not what bench/results/ renders: run `egc-teleop bench report`"
    )
