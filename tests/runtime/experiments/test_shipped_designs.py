"""The shipped-designs table: its rows are the files' own records (worst over the final check and the
re-check), and only files that record a re-check are listed."""
import json

from fjm_runtime.experiments import shipped_designs as sd


def test_rows_are_the_worst_of_both_checks_of_each_file():
    files = sd.rechecked_files()
    assert files and all(json.loads(f.read_text())["recheck"]["draws"] > 0 for f in files)
    for f in files:
        rec = json.loads(f.read_text())
        r = sd.row(f)
        both = [rec["worst_case"], rec["recheck"]["worst_case"]]
        assert r["rms"] == max(max(c["rms_second_half"]) for c in both)
        assert r["at_limit"] == max(max(c["time_at_limit"]) for c in both)
        assert r["runs"] == rec["draws"] + rec["recheck"]["draws"] and r["meets"] is rec["meets"]
        assert (r["model"], r["law"], r["rate"], r["delay"]) == (rec["model"], rec["kind"], rec["rate"], rec["delay"])


def test_table_has_a_line_per_file_with_its_rms_in_mrad():
    lines = sd.table()
    files = sd.rechecked_files()
    assert len(lines) == 2 + len(files)
    for line, f in zip(lines[2:], files):
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[0] == f"`{f.name}`" and cells[9] == f"{sd.row(f)['rms'] * 1e3:.3g}"
