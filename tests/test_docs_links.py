"""The README and docs hold together: every relative link and image of README.md,
CHANGELOG.md, docs/**/*.md and studies/README.md points at a file that exists (and a
``#fragment`` at one of its headings, slugged as GitHub does), every ``vhgen`` command the
README's and the docs' bash blocks show exists (its ``--help`` exits 0), and the README
stays a newcomer's page (at most 25 kB, the details in docs/)."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
README_MAX_BYTES = 25_000

FENCE = re.compile(r"^(```|~~~).*?^\1[ \t]*$", re.S | re.M)
INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1", re.S)
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HEADING = re.compile(r"^(#{1,6})[ \t]+(.+?)[ \t]*#*[ \t]*$", re.M)
BASH_BLOCK = re.compile(r"^```(?:bash|sh|shell|console)\n(.*?)^```", re.S | re.M)
# `vhgen SUB [WORD]` at a command's start: after a line start, a shell operator or a path
# to the script (`.venv/bin/vhgen`, `~/vh/bin/vhgen`)
VHGEN_CMD = re.compile(r"(?:^|[;&|(]\s*|\s)(?:[\w.~-]*/)*vhgen[ \t]+([a-z][\w-]*)"
                       r"(?:[ \t]+([a-z][\w-]*))?", re.M)


def markdown_files() -> list[Path]:
    files = [README, REPO / "CHANGELOG.md", *sorted((REPO / "docs").rglob("*.md")),
             REPO / "studies" / "README.md"]
    return [p for p in files if p.is_file()]


def strip_code(text: str) -> str:
    """The text without fenced blocks and inline code spans (links there are not links)."""
    return INLINE_CODE.sub("", FENCE.sub("", text))


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: link markup reduced to its text, lower case,
    punctuation other than ``-`` and ``_`` dropped, each space a ``-``."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(text: str) -> set[str]:
    """Every heading anchor of a Markdown text (duplicates numbered -1, -2 as GitHub does)."""
    seen: dict[str, int] = {}
    out = set()
    for _, title in HEADING.findall(FENCE.sub("", text)):
        s = slug(title)
        n = seen.get(s, 0)
        seen[s] = n + 1
        out.add(s if n == 0 else f"{s}-{n}")
    return out


def links(text: str) -> list[str]:
    """The targets of the Markdown links and images of a text, outside code."""
    return LINK.findall(strip_code(text))


def broken_links(path: Path) -> list[str]:
    bad = []
    for target in links(path.read_text()):
        if re.match(r"[a-z][a-z0-9+.-]*:", target, re.I):  # http:, https:, mailto:
            continue
        file_part, _, fragment = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        where = f"{path.relative_to(REPO)}: ({target})"
        if not dest.exists():
            bad.append(f"{where} -> no such file {dest}")
        elif REPO not in dest.parents and dest != REPO:
            bad.append(f"{where} -> outside the repository")
        elif fragment and dest.suffix == ".md" and fragment not in anchors(dest.read_text()):
            bad.append(f"{where} -> no heading #{fragment} in {dest.relative_to(REPO)}")
    return bad


def shown_commands(text: str) -> set[tuple[str, str | None]]:
    """(subcommand, next word) of every `vhgen ...` in the bash blocks of a Markdown text."""
    out = set()
    for block in BASH_BLOCK.findall(text):
        block = block.replace("\\\n", " ")
        for line in block.splitlines():
            line = re.sub(r"(^|\s)#.*", "", line)  # a trailing comment
            out.update((m.group(1), m.group(2)) for m in VHGEN_CMD.finditer(line))
    return out


def help_argv(parser: argparse.ArgumentParser, sub: str, word: str | None) -> list[str]:
    """The `--help` call of a shown command: `vhgen SUB --help`, or `vhgen SUB SUBSUB
    --help` when SUB has subcommands (then WORD must be one of them)."""
    top = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert sub in top.choices, f"vhgen has no subcommand {sub!r}"
    nested = [a for a in top.choices[sub]._actions
              if isinstance(a, argparse._SubParsersAction)]
    if not nested:
        return [sub, "--help"]
    assert word in nested[0].choices, f"vhgen {sub} has no subcommand {word!r}"
    return [sub, word, "--help"]


# -- the checks ---------------------------------------------------------------------------

def test_markdown_files_found():
    names = {p.relative_to(REPO).as_posix() for p in markdown_files()}
    assert {"README.md", "CHANGELOG.md", "docs/architecture.md", "docs/performance.md"} <= names


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: p.relative_to(REPO).as_posix())
def test_links_resolve(path):
    bad = broken_links(path)
    assert not bad, "broken links:\n" + "\n".join(bad)


def test_readme_commands_exist(capsys):
    from vhgen.cli import build_parser, main

    shown = set()
    for p in markdown_files():
        shown |= shown_commands(p.read_text())
    readme = shown_commands(README.read_text())
    assert {("generate", "configs"), ("preview", "out")} <= readme, readme
    parser = build_parser()
    for sub, word in sorted(shown, key=str):
        argv = help_argv(parser, sub, word)
        rc = main(argv)
        out = capsys.readouterr().out
        assert rc == 0 and "usage: vhgen" in out, f"vhgen {' '.join(argv)}: exit {rc}"


def test_readme_fits_a_newcomer():
    size = len(README.read_bytes())
    assert size <= README_MAX_BYTES, (
        f"README.md is {size} bytes (at most {README_MAX_BYTES}): move details into docs/")


# -- the helpers themselves -----------------------------------------------------------------

def test_slug_is_githubs():
    assert slug("Scenes: rooms, furniture, clutter, several people") == \
        "scenes-rooms-furniture-clutter-several-people"
    assert slug("Kubernetes (KubeRay)") == "kubernetes-kuberay"
    assert slug("The `scene:` keys") == "the-scene-keys"
    assert slug("A [link](x.md) in it") == "a-link-in-it"
    assert anchors("# A\n## A\n```bash\n# not a heading\n```\n") == {"a", "a-1"}


def test_links_skip_code_and_see_images():
    text = ("[a](x.md) ![img](images/p.png) `[no](y.md)`\n```md\n[no](z.md)\n```\n"
            "[web](https://example.org) [here](#top) [t](x.md \"title\")\n")
    assert links(text) == ["x.md", "images/p.png", "https://example.org", "#top", "x.md"]


def test_broken_links_are_found(tmp_path, monkeypatch):
    repo = tmp_path / "repo"
    repo.mkdir()
    monkeypatch.setattr(f"{__name__}.REPO", repo)
    (repo / "b.md").write_text("# Here it is\n")
    (repo / "a.md").write_text("[ok](b.md#here-it-is) [no](c.md) [bad](b.md#nowhere)\n"
                               "[self](#top) [out](../x.md)\n# Top\n")
    (tmp_path / "x.md").write_text("")
    bad = broken_links(repo / "a.md")
    assert len(bad) == 3
    assert "no such file" in bad[0] and "no heading #nowhere" in bad[1]
    assert "outside the repository" in bad[2]


def test_shown_commands_are_parsed():
    text = ("```bash\n.venv/bin/vhgen generate x.yaml && ~/vh/bin/vhgen preview s -o p.png\n"
            "vhgen forest train a.zarr \\\n    --out f.npz   # vhgen nothing here\n"
            "python vhgen/cli.py\n```\n```text\n$ vhgen info x\n```\n")
    assert shown_commands(text) == {("generate", "x"), ("preview", "s"), ("forest", "train")}


def test_an_unknown_command_fails():
    from vhgen.cli import build_parser

    parser = build_parser()
    assert help_argv(parser, "forest", "train") == ["forest", "train", "--help"]
    assert help_argv(parser, "inspect", "out") == ["inspect", "--help"]
    with pytest.raises(AssertionError, match="no subcommand 'frobnicate'"):
        help_argv(parser, "frobnicate", None)
    with pytest.raises(AssertionError, match="vhgen forest has no subcommand 'grow'"):
        help_argv(parser, "forest", "grow")
