"""The packages' layering: ``ident`` (the science) imports neither ``daq`` nor ``replay``; ``daq`` (outside its
command line) does not import ``replay``; no function imports a project module (no cycle held apart that way).

``ident.cli`` is the science package's I/O edge and the one place in ``ident`` that may compose other
packages' readers and simulated devices; everything else in ``ident`` must load without them. Checked
twice: by importing every such module in a fresh interpreter and looking at ``sys.modules``, and by
reading every file's syntax tree (which also catches an import hidden inside a function).
"""

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

import daq
import ident

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


PROJECT = ("ident", "daq", "replay")
CLI_MODULES = {"daq/cli.py", "daq/bench.py", "daq/__main__.py"}  # daq's command line may compose replay's readers


def _function_imports(path: Path) -> list[str]:
    """Imports of a project module (absolute or relative) inside any function body of ``path``."""
    found = []
    name = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path.name
    for fn in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for node in ast.walk(fn):
            if isinstance(node, ast.ImportFrom) and (node.level > 0 or (node.module or "").split(".")[0] in PROJECT):
                found.append(f"{name}:{node.lineno} from {'.' * node.level}{node.module or ''}")
            elif isinstance(node, ast.Import):
                found += [f"{name}:{node.lineno} import {a.name}" for a in node.names
                          if a.name.split(".")[0] in PROJECT]
    return found


def test_no_function_imports_a_project_module():
    """No import hidden inside a function to dodge a cycle: the layering is visible at the top of each file."""
    files = [f for pkg in PROJECT for f in sorted((ROOT / pkg).rglob("*.py"))]
    assert len(files) > 50
    offenders = [hit for f in files for hit in _function_imports(f)]
    assert offenders == []


def test_the_check_sees_an_import_inside_a_function(tmp_path):
    sample = tmp_path / "probe.py"
    sample.write_text("import numpy\n\ndef f():\n    from .rig import Beam\n    import daq.protocol\n    import json\n")
    assert [h.split(" ", 1)[1] for h in _function_imports(sample)] == ["from .rig", "import daq.protocol"]


def test_daq_outside_its_command_line_never_imports_replay():
    offenders = []
    for f in sorted((ROOT / "daq").rglob("*.py")):
        rel = f.relative_to(ROOT).as_posix()
        if rel in CLI_MODULES:
            continue
        if "replay" in _imported_roots(f):
            offenders.append(rel)
    assert offenders == []


def test_importing_daq_acquisition_loads_no_replay():
    code = ("import sys, daq.driver, daq.recorder, daq.protocol, daq.safeio, daq.transport, daq.viewer\n"
            "print(','.join(sorted(m for m in sys.modules if m.split('.')[0] == 'replay')))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == ""


def test_numpy_is_held_to_its_avx2_kernels_by_every_package_alike():
    """daq/__init__.py says why; ident carries the same value (it cannot import daq). In a fresh process that
    imports a package before numpy, numpy's x86-64 level 4 (AVX-512) kernels are off, and a user's own
    setting is kept."""
    assert ident.NUMPY_SIMD_PIN == daq.NUMPY_SIMD_PIN
    probe = ("import {pkg}, os; from numpy._core._multiarray_umath import __cpu_features__ as f; "
             "print(f.get('X86_V4', False), os.environ['NPY_DISABLE_CPU_FEATURES'])")
    env = {k: v for k, v in os.environ.items() if k != "NPY_DISABLE_CPU_FEATURES"}
    for pkg in ("ident", "daq", "replay"):
        out = subprocess.run([sys.executable, "-c", probe.format(pkg=pkg)], capture_output=True, text=True,
                             env=env, check=True).stdout.split(maxsplit=1)
        assert out == ["False", daq.NUMPY_SIMD_PIN + "\n"], (pkg, out)
    out = subprocess.run([sys.executable, "-c", probe.format(pkg="ident")], capture_output=True, text=True,
                         env={**env, "NPY_DISABLE_CPU_FEATURES": "AVX512_SPR"}, check=True).stdout.split()
    assert out[1] == "AVX512_SPR"


def test_openblas_is_held_to_its_haswell_kernels_where_the_cpu_has_avx2():
    """daq/__init__.py says why (independent seed 116: a false finding with OpenBLAS's SkylakeX kernels).
    In a fresh process that imports a package before numpy, numpy's and scipy's OpenBLAS run the Haswell
    kernels on a CPU with AVX2 and FMA, and nothing is forced on one without; a user's own setting is kept."""
    assert ident.BLAS_PIN == daq.BLAS_PIN == "Haswell" and ident._has_avx2() == daq._has_avx2()
    import threadpoolctl
    if not daq._has_avx2() or not any(i["internal_api"] == "openblas" for i in threadpoolctl.threadpool_info()):
        pytest.skip("no OpenBLAS on a CPU with AVX2 here: the pin sets nothing, or nothing reads it")
    probe = ("import {pkg}, os, numpy, scipy.linalg, threadpoolctl; "
             "print(os.environ.get('OPENBLAS_CORETYPE'), *sorted({{i['architecture'] for i in "
             "threadpoolctl.threadpool_info() if i['internal_api'] == 'openblas'}}))")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    for pkg in ("ident", "daq", "replay"):
        out = subprocess.run([sys.executable, "-c", probe.format(pkg=pkg)], capture_output=True, text=True,
                             env=env, check=True).stdout.split()
        assert out == ["Haswell", "Haswell"], (pkg, out)
    out = subprocess.run([sys.executable, "-c", probe.format(pkg="ident")], capture_output=True, text=True,
                         env={**env, "OPENBLAS_CORETYPE": "Sandybridge"}, check=True).stdout.split()
    assert out == ["Sandybridge", "Sandybridge"]
