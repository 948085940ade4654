"""The default job (material report) runs end to end at a tiny size and writes what it says."""

import pytest

from plasticitynet import report


@pytest.mark.parametrize("dim", [2, 3])
def test_report_writes_table_and_figure(tmp_path, dim, capsys):
    assert report.main(["--out", str(tmp_path), "--materials", "snow", "--dims", str(dim)]) == 0
    figure = tmp_path / f"snow_{dim}d_elastic_region.png"
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = (tmp_path / "report.md").read_text()
    # Every Cam-Clay branch shows up in the table or the figure's branch counts.
    for branch in ("elastic", "compression_tip", "tension_tip", "ellipse"):
        assert branch in text
    # The exact variant lands on the surface; the paper variant measurably does not.
    rows = [line.split("|") for line in text.splitlines() if line.startswith(f"| {dim} | 0.1 |")]
    surface = {row[3].strip(): float(row[5]) for row in rows}
    assert surface["exact"] < 1e-10 < 1e-3 < surface["paper"]
    assert "wrote" in capsys.readouterr().out
    assert not list(tmp_path.glob("*.tmp*"))
