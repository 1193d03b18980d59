"""CLI fuzz: every subcommand and every flag, enumerated from the argparse parser (a new
flag is covered without editing this file), fed out-of-range, wrong-type and missing
values: exit code 2, one line on stderr naming the flag, no traceback, and nothing run.

Most cases call ``vhgen.cli.main`` in-process with the commands replaced by a recorder;
a few go through the installed ``vhgen`` console script."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from vhgen import cli
from vhgen.cliargs import ArgType

GARBAGE = ["", "abc", "-3", "1e999", "nan", "/nonexistent/vhgen/x"]


def _leaves(parser: argparse.ArgumentParser, path=()):
    """(subcommand path, parser) of every runnable subcommand."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield path, parser
        return
    for name, p in subs[0].choices.items():
        yield from _leaves(p, (*path, name))


def _takes_value(a: argparse.Action) -> bool:
    return a.nargs != 0 and not isinstance(a, (argparse._HelpAction,
                                               argparse._SubParsersAction))


def _example(a: argparse.Action) -> str:
    if a.choices:
        return str(next(iter(a.choices)))
    assert isinstance(a.type, ArgType), f"{a.dest} has no checked type"
    return a.type.example


def _base(parser: argparse.ArgumentParser) -> tuple[list[str], list[str]]:
    """(positionals, required options) with valid-looking example values."""
    pos, req = [], []
    for a in parser._actions:
        if not _takes_value(a):
            continue
        if not a.option_strings:
            pos.append(_example(a))
        elif a.required:
            req += [a.option_strings[0], _example(a)]
    return pos, req


def _without(req: list[str], flag: str) -> list[str]:
    """The required options without ``flag`` and its value."""
    if flag not in req:
        return req
    i = req.index(flag)
    return [*req[:i], *req[i + 2:]]


def _bad_values(a: argparse.Action) -> list[str]:
    if a.choices:
        return ["", "no-such-choice", "1"]
    assert isinstance(a.type, ArgType), (
        f"flag {a.option_strings or a.dest} takes a value without a checked type: give it "
        "a vhgen.cliargs type (or choices) so bad input fails in one line")
    return list(a.type.invalid)


CASES = []
for _path, _p in _leaves(cli.build_parser()):
    for _a in _p._actions:
        if _takes_value(_a):
            CASES.append((_path, _a.option_strings[0] if _a.option_strings else _a.dest))


def _example_files(where: Path) -> None:
    """The files the examples of existing-file arguments name (``example.png``, ...)."""
    for _, parser in _leaves(cli.build_parser()):
        for a in parser._actions:
            if isinstance(a.type, ArgType) and a.type.__name__ == "file":
                (where / a.type.example).write_bytes(b"x")


@pytest.fixture
def recorder(monkeypatch):
    """build_parser with every command replaced: a case that parses records, runs nothing."""
    calls = []
    real = cli.build_parser

    def build():
        p = real()
        for _, leaf in _leaves(p):
            leaf.set_defaults(func=lambda args: calls.append(args) or 0)
        return p

    monkeypatch.setattr(cli, "build_parser", build)
    return calls


def _run(argv, capsys) -> tuple[int, str]:
    try:
        code = cli.main(argv)
    except SystemExit as e:
        code = e.code
    return code, capsys.readouterr().err


def test_every_flag_is_covered():
    assert len(CASES) >= 30
    names = {f for _, f in CASES}
    for flag in ("--num-workers", "--min-angle-deg", "--frame-step", "--pose", "--frames",
                 "config", "inputs", "store"):
        assert flag in names


@pytest.mark.parametrize("path,flag", CASES, ids=[" ".join(c[0]) + " " + c[1] for c in CASES])
def test_bad_values_fail_in_one_line(path, flag, recorder, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # example inputs and outputs ("out.png", ...) live here
    _example_files(tmp_path)
    parser = dict(_leaves(cli.build_parser()))[path]
    action = next(a for a in parser._actions if _takes_value(a)
                  and (a.option_strings[:1] == [flag] or (not a.option_strings
                                                          and a.dest == flag)))
    pos, req = _base(parser)
    for bad in _bad_values(action):
        if action.option_strings:
            argv = [*path, *pos, *_without(req, flag), flag, bad]
        else:
            i = [a for a in parser._actions if _takes_value(a)
                 and not a.option_strings].index(action)
            argv = [*path, *pos[:i], bad, *pos[i + 1:], *req]
        code, err = _run(argv, capsys)
        assert code == 2, (argv, err)
        assert "Traceback" not in err, argv
        lines = err.strip().splitlines()
        assert len(lines) == 1, (argv, err)
        assert flag in lines[0] or action.dest in lines[0], (argv, err)
    assert recorder == []  # nothing ran


@pytest.mark.parametrize("path,flag", [c for c in CASES if c[1].startswith("-")],
                         ids=[" ".join(c[0]) + " " + c[1] for c in CASES
                              if c[1].startswith("-")])
def test_missing_value(path, flag, recorder, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _example_files(tmp_path)
    parser = dict(_leaves(cli.build_parser()))[path]
    action = next(a for a in parser._actions if a.option_strings[:1] == [flag])
    if action.nargs in ("*", "?"):
        return  # an empty list is a valid value of these
    pos, req = _base(parser)
    code, err = _run([*path, *pos, *_without(req, flag), flag], capsys)
    assert code == 2 and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and flag in err
    assert recorder == []


@pytest.mark.parametrize("path", [p for p, _ in _leaves(cli.build_parser())],
                         ids=[" ".join(p) for p, _ in _leaves(cli.build_parser())])
def test_missing_required_and_unknown_flag(path, recorder, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _example_files(tmp_path)
    parser = dict(_leaves(cli.build_parser()))[path]
    pos, req = _base(parser)
    if req or any(not a.option_strings and _takes_value(a) and a.nargs not in ("*", "?")
                  for a in parser._actions):
        code, err = _run(list(path), capsys)
        assert code == 2 and len(err.strip().splitlines()) == 1 and "required" in err
    code, err = _run([*path, *pos, *req, "--no-such-flag"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--no-such-flag" in err
    assert recorder == []


def test_valid_examples_parse(recorder, capsys, tmp_path, monkeypatch):
    """The examples the fuzz builds on are accepted (else the cases above prove little)."""
    monkeypatch.chdir(tmp_path)
    _example_files(tmp_path)
    for path, parser in _leaves(cli.build_parser()):
        pos, req = _base(parser)
        code, err = _run([*path, *pos, *req], capsys)
        assert code == 0, (path, err)
    assert len(recorder) == len(list(_leaves(cli.build_parser())))


def test_corpus_build_fails_before_reading(monkeypatch, capsys, shared_mocap):
    """The threshold is refused before a single file is read."""
    import vhgen.mocap.corpus as corpus

    def boom(*a, **kw):
        raise AssertionError("build_corpus must not start")

    monkeypatch.setattr(corpus, "build_corpus", boom)
    code, err = _run(["corpus", "build", str(shared_mocap), "-o", "/tmp/x.parquet",
                      "--min-angle-deg", "0"], capsys)
    assert code == 2 and "--min-angle-deg" in err and "(0, 180)" in err


def test_bad_scene_file_names_the_field(tmp_path, capsys):
    bad = tmp_path / "s.yaml"
    bad.write_text("name: s\nmotions: [builtin:demo]\nposes: {frame_step: 0}\n")
    code, err = _run(["generate", str(bad), "--out", str(tmp_path / "o.zarr")], capsys)
    assert code == 2 and "poses.frame_step" in err and str(bad) in err
    assert len(err.strip().splitlines()) == 1
    for line, field in (("num_workers: two", "num_workers"), ("sensor: 5", "sensor"),
                        ("labels: nosuch", "labels"), ("retarget: [a]", "retarget"),
                        ("labels: mine.yaml", "mine.yaml")):
        bad.write_text(f"name: s\nmotions: [builtin:demo]\n{line}\n")
        code, err = _run(["generate", str(bad), "--out", str(tmp_path / "o.zarr")], capsys)
        assert code == 2 and field in err and str(bad) in err, (line, err)
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_internal_errors_keep_their_traceback(monkeypatch):
    """A bug is not a user error: it is not turned into one line."""
    import vhgen.job_config

    def bug(*a, **kw):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(vhgen.job_config.JobConfig, "load", bug)
    with pytest.raises(ZeroDivisionError):
        cli.main(["generate", "default"])


@pytest.mark.parametrize("argv,flag", [
    (["generate", "default", "--num-workers", "-3"], "--num-workers"),
    (["corpus", "build", ".", "-o", "x.parquet", "--frame-step", "0"], "--frame-step"),
    (["avatar", "export", "-o", "x.glb", "--pose", "x.bvh:abc"], "--pose"),
    (["preview", ".", "-o", "x.png", "--frames", "1,x"], "--frames"),
])
def test_console_script(argv, flag, tmp_path):
    """The real entry point: one line, exit 2, no traceback."""
    exe = Path(sys.executable).with_name("vhgen")
    r = subprocess.run([str(exe), *argv], capture_output=True, text=True, cwd=tmp_path,
                       timeout=60)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert flag in r.stderr and r.stdout == ""


def test_quiet_and_verbose_set_the_log_level(recorder, capsys):
    import logging

    vh = logging.getLogger("vhgen")
    progress = logging.getLogger("vhgen.progress")
    for argv, level, shown in ((["info", "."], logging.WARNING, logging.INFO),
                               (["-q", "info", "."], logging.WARNING, logging.WARNING),
                               (["info", ".", "--verbose"], logging.DEBUG, logging.DEBUG),
                               (["info", ".", "--quiet"], logging.WARNING, logging.WARNING)):
        assert cli.main(argv) == 0
        assert vh.level == level and progress.level == shown, argv
    assert cli.main(["-q", "info", ".", "-v"]) == 2
    assert "exclude each other" in capsys.readouterr().err
