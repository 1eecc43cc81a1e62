"""Quick runs of the studies and their report (the full runs are marked slow)."""

import json

import pytest


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


def _figures(folder):
    return sorted(p.name for p in folder.glob("*.png") if p.stat().st_size > 10_000)


def test_constrained_quick(tmp_path):
    from studies import constrained

    metrics = constrained.run(tmp_path, quick=True)
    violations = metrics["violation_fraction"]
    assert violations["dmp_unconstrained"] > 0.5  # the bounds are tight
    constrained_name = [
        m for m in violations if "dmp" in m and "constrained" in m and "unconstrained" not in m
    ][0]
    assert violations[constrained_name] == 0.0
    assert metrics["solve_ms_median"][constrained_name] > 0
    assert len(_figures(tmp_path)) >= 3


def test_rl_quick(tmp_path):
    from studies import rl

    metrics = rl.run(tmp_path, quick=True)
    assert metrics["optimum_return"] > metrics["initial_return"]
    assert {"enac", "ereinforce"} <= set(metrics["trials_to_95"])
    assert all(t is None or t > 0 for t in metrics["trials_to_95"].values())
    assert metrics["trials_to_95"]["enac"] <= 400
    assert len(_figures(tmp_path)) >= 2


def test_recognition_quick(tmp_path):
    from studies import recognition

    metrics = recognition.run(tmp_path, quick=True)
    assert 0.9 <= metrics["accuracy_loo"] <= 1.0
    assert metrics["accuracy_transformed"] == metrics["accuracy_loo"]
    assert len(_figures(tmp_path)) >= 2


def test_biped_quick(tmp_path):
    from studies import biped

    metrics = biped.run(tmp_path, quick=True)
    assert metrics["fell"] is False and metrics["steps_walked"] >= 10
    assert {"steps_to_2pct", "cost_of_transport", "real_time_factor"} <= set(metrics)
    assert len(_figures(tmp_path)) >= 3


def test_report_links_every_figure(tmp_path):
    """report.html names each study, embeds each figure it links, and renders if a browser
    is installed (headless Chromium from the Debian package)."""
    import re
    import shutil
    import subprocess

    from studies import imitation
    from studies.report import write_report

    imitation.run(tmp_path / "imitation", quick=True)
    page = write_report(tmp_path).read_text()
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    assert '<section id="imitation">' in page and "rmse_mm" in page
    images = re.findall(r'<img src="([^"]+)"', page)
    assert len(images) == 3
    assert all((tmp_path / image).stat().st_size > 10_000 for image in images)
    browser = shutil.which("chromium")
    if browser is None:
        return
    shot = tmp_path / "report.png"
    subprocess.run(
        [
            browser,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={tmp_path / 'profile'}",
            f"--screenshot={shot}",
            "--window-size=1200,2000",
            (tmp_path / "report.html").as_uri(),
        ],
        check=True,
        capture_output=True,
        timeout=120,
    )
    assert shot.stat().st_size > 50_000  # a blank page compresses to a few kB


def test_report_embeds_listed_videos_and_says_why_they_were_skipped(tmp_path):
    """Each video a study lists under ``videos`` is embedded; ``videos_skipped`` is shown."""
    import json
    import re

    from studies.report import write_report

    for name, videos, skipped in (("humanoid", ["drumming.webp"], None), ("biped", [], "no GL")):
        (tmp_path / name).mkdir()
        metrics = {"videos": videos, "videos_skipped": skipped}
        (tmp_path / name / "metrics.json").write_text(json.dumps(metrics))
    page = write_report(tmp_path).read_text()
    assert re.findall(r'<img src="([^"]+)"', page) == ["humanoid/drumming.webp"]
    assert "videos skipped: no GL" in page
    assert "<details open>" not in page  # metrics collapsed by default
