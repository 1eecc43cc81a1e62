"""Quick runs of the studies and the command line (the full runs are marked slow)."""

import json

import pytest

from dmpopt import cli


def test_imitation_quick(tmp_path):
    from studies import imitation

    metrics = imitation.run(tmp_path, quick=True, seed=1)
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["rmse_mm"]["30"] == pytest.approx(metrics["rmse_mm"]["30"])
    assert saved["nonfinite"] == 0
    assert saved["rmse_mm"]["100"] < saved["rmse_mm"]["30"] < saved["rmse_mm"]["10"]
    assert saved["rmse_mm"]["30"] < 0.1
    assert saved["goal_shift_error_mm"]["worst"] < 1.0
    assert {"seed", "versions", "parameters"} <= set(saved)
    for figure in ("reproductions.png", "new_goals.png", "rmse_vs_basis.png"):
        assert (tmp_path / figure).stat().st_size > 10_000


@pytest.mark.slow
def test_imitation_full(tmp_path):
    from studies import imitation

    metrics = imitation.run(tmp_path)
    assert metrics["n_demos"] == 210 and metrics["nonfinite"] == 0
    assert metrics["rmse_mm"]["30"] <= 0.03
    assert metrics["goal_shift_error_mm"]["median"] <= 0.3
    assert metrics["goal_shift_error_mm"]["worst"] <= 1.0


def test_cli_lists_studies(capsys):
    assert cli.main(["study", "list"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0].startswith("imitation")


def test_cli_rejects_unknown_study(capsys):
    with pytest.raises(SystemExit):
        cli.main(["study", "run", "nonsense"])
    assert "unknown study 'nonsense'" in capsys.readouterr().err
