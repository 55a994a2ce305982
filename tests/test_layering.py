"""The packages' layering: ``ident`` (the science) imports neither ``daq`` nor ``replay``.

``ident.cli`` is the science package's I/O edge and the one place in ``ident`` that may compose other
packages' readers and simulated devices; everything else in ``ident`` must load without them. Checked
twice: by importing every such module in a fresh interpreter and looking at ``sys.modules``, and by
reading every file's syntax tree (which also catches an import hidden inside a function).
"""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _science_modules() -> list[str]:
    out = []
    for f in sorted((ROOT / "ident").rglob("*.py")):
        rel = f.relative_to(ROOT).with_suffix("")
        parts = list(rel.parts)
        if "cli" in parts or parts[-1] == "__main__":
            continue
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.append(".".join(parts))
    return out


def _imported_roots(path: Path) -> set[str]:
    roots = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            roots |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split(".")[0])
    return roots


def test_importing_the_science_loads_neither_daq_nor_replay():
    modules = _science_modules()
    assert "ident.rig" in modules and "ident.live.pipeline" in modules  # the walk found the packages
    code = ("import importlib, sys\n"
            f"for m in {modules!r}: importlib.import_module(m)\n"
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('daq', 'replay'))\n"
            "print(','.join(bad))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "", f"importing ident loaded {out.stdout.strip()}"


def test_no_science_file_names_daq_or_replay_anywhere():
    offenders = []
    for f in sorted((ROOT / "ident").rglob("*.py")):
        if "cli" in f.relative_to(ROOT).parts:
            continue
        bad = _imported_roots(f) & {"daq", "replay"}
        if bad:
            offenders.append(f"{f.relative_to(ROOT)} imports {sorted(bad)}")
    assert offenders == []
