"""The ident command line: the report and JSON of `ident duffing`, and one-line errors."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from clitools import run_main
from ident.cli.main import main


def run(*args, **kw):
    return subprocess.run([sys.executable, "-m", "ident", *args], capture_output=True, text=True, **kw)


@pytest.fixture(scope="module")
def quick_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("duffing")
    proc = run("duffing", "--quick", "--no-progress", "--json", str(out / "d.json"), "--report",
               str(out / "report"), timeout=600)
    assert proc.returncode == 0, proc.stderr
    return out, proc


def test_duffing_json_has_the_documented_fields(quick_report):
    out, _ = quick_report
    js = json.loads((out / "d.json").read_text())
    assert js["clean"]["coefficients"]["x2'"]["x1^3"] == pytest.approx(-0.6, abs=1e-6)
    assert set(js["noise_example"]["coefficients"]) == {"x1'", "x2'"}
    assert js["noise_example"]["snr_db"] == pytest.approx(22.33, abs=0.5)
    assert js["noise_example"]["error_percent"] < 5
    assert len(js["noise_sweep"]) == 4
    assert all(len(r["error_percent"]) == 3 and "eta" in r and "snr_db" in r for r in js["noise_sweep"])
    assert js["embedding"]["dimension"] == 3 and js["embedding"]["coefficients"]
    # Table 3: x1's delay embedding, identified and integrated, reproduces the attractor (once a test of its
    # own in test_duffing.py, which computed the same study on the same data a second time)
    assert js["embedding"]["nrmse"] < 0.1 and js["embedding"]["error_percent"] < 5.0


def test_duffing_report_folder(quick_report):
    out, _ = quick_report
    rep = out / "report"
    for name in ("README.md", "table1_clean.csv", "table2_noise.csv", "table3_embedding.csv",
                 "fig4_noise_sweep.csv", "fig2_duffing.png", "fig3_pareto.png", "fig4_error_vs_snr.png",
                 "fig5_embedding.png"):
        assert (rep / name).stat().st_size > 0, name
    assert (rep / "fig2_duffing.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "![Figure 4]" in (rep / "README.md").read_text()


@pytest.mark.parametrize("args", [["duffing", "--bogus"], ["nosuchcommand"], ["duffing", "--seed", "x"]])
def test_usage_errors_are_one_line_and_exit_2(args):
    # through main() in this process; the console entry point in a process of its own is the test below
    code, _, err, tb = run_main(main, args)
    assert tb is None and code == 2 and len(err.strip().splitlines()) == 1, (code, err, tb)


def test_value_errors_are_one_line_and_exit_2(tmp_path):
    (tmp_path / "afile").write_text("x")
    proc = run("duffing", "--quick", "--no-progress", "--report", str(tmp_path / "afile"))
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr


def test_a_reader_that_goes_away_ends_the_command_quietly():
    # `replay info F | head -3`: the pipe closed before the output was written had printed
    # "replay info: error: [Errno 32] Broken pipe" (or Python's "Exception ignored" at exit)
    rec = Path(__file__).resolve().parents[1] / "recordings" / "linear.mcap"
    p = subprocess.Popen([sys.executable, "-m", "replay", "info", str(rec)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141 and err == "", err


def test_a_broken_pipe_that_is_not_the_output_is_an_error_as_any_other(capsys):
    # (a port or a child's pipe that breaks is no reader gone: one line and exit 2, not a silent 141)
    from ident.cli import run_guarded

    def breaks(_):
        raise BrokenPipeError(32, "Broken pipe")

    assert run_guarded("ident x", breaks, None) == 2
    assert capsys.readouterr().err == "ident x: error: [Errno 32] Broken pipe\n"
