"""The scaling section's arithmetic: fitted exponents, targets and the rendered table (no derive run)."""
import math

from bench import report_blocks
from bench.scaling import TARGETS, fit_exponents, run_measured, target_rows


def _runs(c: float, e: float):
    return [{"n": n, **{q: c * n ** e for q in ("derive_seconds", "peak_bytes", "alpha_beta_ops", "ad_ops",
                                               "all_ops", "c_bytes")}, "gcc_seconds": None}
            for n in (7, 14, 21, 30)]


def test_fit_recovers_a_known_power_law_and_skips_missing_values():
    fits = fit_exponents(_runs(3.0, 2.0))
    assert math.isclose(fits["alpha_beta_ops"]["e"], 2.0, rel_tol=1e-12)
    assert math.isclose(fits["alpha_beta_ops"]["c"], 3.0, rel_tol=1e-12)
    assert "gcc_seconds" not in fits  # never measured: no fit


def test_targets_met_and_missed_and_rendered():
    runs = _runs(1.0, 2.0)  # n = 21: 441 for every quantity, n = 30: 900
    rows = {r["what"]: r for r in target_rows(runs, {"alpha_beta_ops": 6000, "alpha_beta_us": None})}
    assert rows["n = 21 alpha_beta_ops"]["ok"] is True
    assert rows["n = 21 derive_seconds"]["ok"] is False  # 441 s > 10 s
    assert rows["panda alpha_beta_ops"]["ok"] is False
    assert rows["panda alpha_beta_us"]["ok"] is None
    assert len(rows) == len(TARGETS) + 2
    text = "\n".join(report_blocks.scaling_lines({"scaling": {"runs": runs, "fits": fit_exponents(runs),
                                                        "targets": list(rows.values())}}))
    assert "**missed**" in text and "| 30 |" in text and "2.00" in text


def test_run_measured_reports_the_childs_peak_memory():
    import sys
    # a child that holds ~60 MB: the peak must see it, far above an idle interpreter's
    res = run_measured([sys.executable, "-c", "b = bytearray(60 * 1024 * 1024); b[::4096] = b'x' * len(b[::4096])"],
                       ".", None)
    assert res["returncode"] == 0
    assert res["peak_bytes"] > 60 * 1024 * 1024


def test_run_measured_does_not_count_the_benchs_own_memory():
    """A small child measured from a big parent reads its own peak, not the parent's (Linux keeps
    ``ru_maxrss`` across exec: forked straight from a 300 MB parent, ``python -c pass`` read 329 MB)."""
    import sys
    held = bytearray(300 * 1024 * 1024)
    held[::4096] = b"x" * len(held[::4096])  # touch every page: resident in this process
    res = run_measured([sys.executable, "-c", "pass"], ".", None)
    assert res["returncode"] == 0
    assert 1e6 < res["peak_bytes"] < 100e6, res["peak_bytes"]
    del held


def test_run_measured_passes_the_exit_status_and_output_through():
    import sys
    res = run_measured([sys.executable, "-c", "import sys; print('out'); print('err', file=sys.stderr); sys.exit(3)"],
                       ".", None)
    assert (res["returncode"], res["stdout"], res["stderr"]) == (3, "out\n", "err\n")
    assert res["peak_bytes"] > 1e6 and res["seconds"] > 0

