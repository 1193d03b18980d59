"""The package graph points down: a module imports only its own layer and the ones below.

Every import under vhgen/ counts, including those inside functions and under
``TYPE_CHECKING``, and ``from vhgen import X`` (the submodule X, or else the package's
``__init__``, which is in the top layer). Packages of one layer may import each other, but
never in a circle. The order is written once, in LAYERS (lowest first), and the modules
allowed to import a backend once, in BACKENDS; ``docs/architecture.md`` states both and a
test checks that it says the same.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import vhgen

ROOT = Path(vhgen.__file__).parent

# Lowest first. A module belongs to the first entry that is a prefix of its dotted name
# (without the leading "vhgen."); modules in the same layer may import each other.
LAYERS: list[tuple[str, ...]] = [
    ("errors", "yamlio", "version"),
    ("rotations", "camera", "assets", "executor", "geom"),
    ("mocap", "body", "sensor", "depthfile"),
    ("realism",),
    ("scene",),
    ("store",),
    ("job_config", "cliargs"),
    ("render", "preview"),
    ("pipeline",),
    ("quality",),
    ("forest",),
    ("dataset", "cli", "__init__", "__main__"),
]
# Backends: which modules may import them at all (prefix match on the dotted name).
# vhgen.dataset.to_ray is the one reader that is a Ray entry point (Ray Data), imported
# inside that function only; `import vhgen` staying Ray-free is checked below.
BACKENDS = {"ray": ("executor.raypool", "dataset"), "moderngl": ("render",),
            "glcontext": ("render",)}
ARCHITECTURE = ROOT.parent / "docs" / "architecture.md"


def _layer(mod: str) -> int:
    for i, names in enumerate(LAYERS):
        if any(mod == n or mod.startswith(n + ".") for n in names):
            return i
    raise AssertionError(f"vhgen.{mod} is in no layer: add it to LAYERS in {__file__}")


def _is_module(dotted: str) -> bool:
    p = ROOT.parent.joinpath(*dotted.split("."))
    return p.with_suffix(".py").is_file() or (p / "__init__.py").is_file()


def _module(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__" and len(parts) > 1:
        parts.pop()
    return ".".join(parts)


def _imports(path: Path, mod: str) -> list[tuple[int, str]]:
    """(line, absolute dotted name) of every import in the file."""
    out = []
    package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(["vhgen", *package.split(".")][: len(package.split(".")) + 2
                                                                  - node.level])
                name = f"{base}.{node.module}" if node.module else base
            else:
                name = node.module or ""
            # `from vhgen.sensor import effects` imports the submodule; `from vhgen import
            # __version__` imports the package's __init__ (the top layer)
            subs = [f"{name}.{a.name}" for a in node.names
                    if name.startswith("vhgen") and _is_module(f"{name}.{a.name}")]
            if name == "vhgen" and len(subs) < len(node.names):
                out.append((node.lineno, "vhgen.__init__"))
            elif name != "vhgen":
                out.append((node.lineno, name))
            out += [(node.lineno, sub) for sub in subs]
    return out


def _edges():
    for path in sorted(ROOT.rglob("*.py")):
        mod = _module(path)
        for line, name in _imports(path, mod):
            yield path, line, mod, name


def test_no_upward_import():
    bad = []
    for path, line, mod, name in _edges():
        if name.startswith("vhgen."):
            target = name[len("vhgen."):]
            if _layer(target) > _layer(mod):
                bad.append(f"{path.relative_to(ROOT.parent)}:{line}: vhgen.{mod} -> {name}")
    assert not bad, "upward imports:\n" + "\n".join(bad)


def test_backends_only_where_allowed():
    bad = []
    for path, line, mod, name in _edges():
        top = name.split(".")[0]
        allowed = BACKENDS.get(top)
        if allowed is not None and not any(mod == a or mod.startswith(a + ".")
                                           for a in allowed):
            bad.append(f"{path.relative_to(ROOT.parent)}:{line}: vhgen.{mod} imports {top}")
    assert not bad, "backend imports outside their modules:\n" + "\n".join(bad)


def _package_graph() -> dict[str, set[str]]:
    """Top-level package (or module) -> the other top-level ones it imports."""
    graph: dict[str, set[str]] = {}
    for _, _, mod, name in _edges():
        if name.startswith("vhgen."):
            a, b = mod.split(".")[0], name.split(".")[1]
            if a != b:
                graph.setdefault(a, set()).add(b)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_package_cycles():
    """Packages of the same layer may import each other, but not in a circle."""
    cycles = _cycles(_package_graph())
    assert not cycles, f"packages importing each other in a circle: {cycles}"


def test_cycle_finder_sees_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_architecture_doc_states_the_layers_and_backends():
    """docs/architecture.md says what LAYERS and BACKENDS say."""
    text = ARCHITECTURE.read_text()
    order = " < ".join("`" + " ".join(names) + "`" for names in LAYERS)
    assert order in " ".join(text.split()), f"architecture.md must state the layers: {order}"
    for backend, mods in (("Ray", BACKENDS["ray"]), ("GL", BACKENDS["moderngl"])):
        line = next((ln for ln in text.splitlines() if ln.startswith(f"- {backend} only in")),
                    None)
        assert line is not None, f"architecture.md has no '- {backend} only in' line"
        assert sorted(re.findall(r"`vhgen\.([\w.]+)`", line)) == sorted(mods), line


def test_every_module_has_a_layer():
    for path in ROOT.rglob("*.py"):
        _layer(_module(path))


def module_name_clashes(root: Path) -> list[str]:
    """Module basenames under ``root`` that say two things: two modules of one name (each
    ``__init__.py`` aside), or a module named like a package (``render/scene.py`` beside
    ``scene/``). A newcomer who finds ``kernels.py`` should know which one it is."""
    modules: dict[str, list[str]] = {}
    for p in sorted(root.rglob("*.py")):
        if p.name != "__init__.py":
            modules.setdefault(p.stem, []).append(str(p.relative_to(root.parent)))
    packages = {p.parent.name: str(p.parent.relative_to(root.parent))
                for p in root.rglob("__init__.py") if p.parent != root}
    bad = [f"{name}.py: {', '.join(paths)}" for name, paths in modules.items()
           if len(paths) > 1]
    bad += [f"{', '.join(paths)} named like the package {packages[name]}/"
            for name, paths in modules.items() if name in packages]
    return bad


def test_module_names_are_unique():
    bad = module_name_clashes(ROOT)
    assert not bad, "module names that say two things:\n" + "\n".join(bad)


def test_module_name_clash_finder_sees_clashes(tmp_path):
    pkg = tmp_path / "pkg"
    for f in ("__init__.py", "cli.py", "a/__init__.py", "a/cli.py", "b/__init__.py",
              "b/x.py", "c/__init__.py", "c/a.py"):
        (pkg / f).parent.mkdir(parents=True, exist_ok=True)
        (pkg / f).write_text("")
    assert module_name_clashes(pkg) == ["cli.py: pkg/a/cli.py, pkg/cli.py",
                                        "pkg/c/a.py named like the package pkg/a/"]


def test_import_vhgen_is_light():
    code = ("import sys, time; t = time.perf_counter(); import vhgen; "
            "vhgen.SensorConfig.load('kinect_v1_full'); "
            "print(time.perf_counter() - t); "
            "bad = [m for m in ('scipy.ndimage', 'scipy', 'numba', 'vhgen.sensor.sensor_kernels', "
            "'moderngl', 'glcontext', 'ray', 'zarr', 'pyarrow') if m in sys.modules]; "
            "print(','.join(bad)); sys.exit(1 if bad else 0)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


def test_no_import_cycles():
    """No module reaches itself through imports (inside functions included), so no
    import is ever placed in a function to dodge a cycle."""
    graph: dict[str, set[str]] = {}
    mods = {_module(p) for p in ROOT.rglob("*.py")}
    for _, _, mod, name in _edges():
        target = name[len("vhgen."):] if name.startswith("vhgen.") else None
        while target and target not in mods:  # `from vhgen.x import name`
            target = target.rpartition(".")[0]
        if target and target != mod:
            graph.setdefault(mod, set()).add(target)

    def reach(start: str) -> set[str]:
        seen, todo = set(), [start]
        while todo:
            for n in graph.get(todo.pop(), ()):
                if n not in seen:
                    seen.add(n)
                    todo.append(n)
        return seen

    def nested(a: str, b: str) -> bool:  # a package and its own submodule
        return a.startswith(b + ".") or b.startswith(a + ".") or "__init__" in (a, b)

    cycles = sorted(m for m in graph
                    if any(m in reach(n) and not nested(m, n) for n in reach(m) - {m}))
    assert not cycles, f"modules on an import cycle: {cycles}"


if __name__ == "__main__":
    # `python tests/test_layers.py > graph.dot`: the package graph (dot -Tsvg), layer ranks
    edges = {(mod.split(".")[0], name.split(".")[1]) for _, _, mod, name in _edges()
             if name.startswith("vhgen.") and mod.split(".")[0] != name.split(".")[1]}
    print("digraph vhgen {\n  rankdir=BT;")
    for i, names in enumerate(LAYERS):
        nodes = "; ".join('"' + n + '"' for n in names)
        print(f"  {{rank=same; {nodes}}}  // layer {i}")
    for a, b in sorted(edges):
        print(f'  "{a}" -> "{b}";')
    print("}")
