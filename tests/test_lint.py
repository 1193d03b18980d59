import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def test_ruff_clean():
    ruff = shutil.which("ruff", path=str(Path(sys.executable).parent)) or shutil.which("ruff")
    assert ruff, "ruff is part of the dev extra"
    res = subprocess.run([ruff, "check", "vhgen", "jobs", "scripts", "benchmarks", "studies",
                          "tests"],
                         cwd=REPO, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


def test_mypy_clean():
    """The type checker configured in pyproject.toml ([tool.mypy]) passes on vhgen/ and
    studies/."""
    res = subprocess.run([sys.executable, "-m", "mypy"], cwd=REPO, capture_output=True,
                         text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "Success" in res.stdout


def test_no_merge_conflict_markers():
    """No file of the repository keeps a merge's conflict markers (docs included)."""
    import re

    marker = re.compile(r"^(<{7}|>{7})( |$)", re.M)
    bad = []
    for sub in ("vhgen", "docs", "configs", "tests", "benchmarks", "studies", "jobs",
                "scripts", "cluster"):
        for p in (REPO / sub).rglob("*"):
            if p.suffix in {".py", ".md", ".yaml", ".yml", ".toml", ".txt", ".glsl", ".sh"}:
                if marker.search(p.read_text(errors="replace")):
                    bad.append(str(p.relative_to(REPO)))
    for p in REPO.glob("*"):
        if p.is_file() and p.suffix in {".md", ".toml", ".py", ""} and p.stat().st_size < 2e6:
            if marker.search(p.read_text(errors="replace")):
                bad.append(p.name)
    assert not bad, f"conflict markers in {bad}"
