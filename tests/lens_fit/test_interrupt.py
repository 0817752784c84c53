"""Ctrl-C during a fit (SIGINT to the petzval-fit process): the fit ends at its next evaluation
and its best point so far is written in full (fitted lens, LRTF, report), exit status 130.
A report folder reused from an earlier fit keeps none of that fit's capture images."""

from __future__ import annotations

import json
import signal
import subprocess
import time

from conftest import OUT


def test_sigint_writes_the_best_point_so_far(optiland_fit, petzval_fit_bin):
    out = OUT / "interrupt"
    report = out / "report"
    report.mkdir(parents=True, exist_ok=True)
    (report / "09-earlier-capture.png").write_bytes(b"stale")
    (report / "notes.txt").write_text("the user's")
    cmd = [
        str(petzval_fit_bin),
        str(OUT / "train.toml"),
        "-o",
        str(out / "fitted.toml"),
        "--lrtf",
        str(out / "fitted.lrtf"),
        "--report",
        str(report),
        "--time-limit",
        "600",
        "--rays",
        "65536",
        "--quiet",
    ]
    t0 = time.monotonic()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = p.stdout.readline()  # printed once the captures are loaded, as the fit starts
    assert "captures" in first, first + p.stderr.read()
    time.sleep(2.0)
    p.send_signal(signal.SIGINT)
    stdout, stderr = p.communicate(timeout=120)
    took = time.monotonic() - t0
    assert p.returncode == 130, f"{p.returncode}\n{stdout}\n{stderr}"
    assert took < 60, f"{took:.1f} s for a fit interrupted after 2 s (its limit was 600 s)"
    assert "interrupted" in stderr, stderr
    fit = json.loads((report / "fit.json").read_text())
    assert fit["lm_stop"]["reason"] == "interrupted"
    assert any("interrupted" in w for w in fit["warnings"]), fit["warnings"]
    value = fit["params"][optiland_fit["param"]]["value"]
    assert abs(value / optiland_fit["truth_radius"] - 1) <= 0.05, value  # within its bounds
    assert (out / "fitted.toml").stat().st_size > 0
    assert (out / "fitted.lrtf").stat().st_size > 0
    assert not (report / "09-earlier-capture.png").exists()
    assert (report / "notes.txt").exists()
    assert len(list(report.glob("0?-train*.png"))) == 6
    print(f"interrupt: {took:.1f} s, {fit['iterations']}, {stdout.splitlines()[1:3]}")
