"""One HTML page with every study's figures, the paper's claim and the measured numbers."""

from __future__ import annotations

import html
import importlib
import json
from pathlib import Path

from .common import write_text_atomic


def _claim(name: str) -> str:
    module = importlib.import_module(f"studies.{name}")
    return (module.__doc__ or "").strip()


def write_report(out_dir, names=None) -> Path:
    """Write ``report.html`` in ``out_dir`` from the study folders in it.

    Parameters
    ----------
    out_dir : path
        The folder holding one sub-folder per study (``<name>/metrics.json`` and figures).
    names : list of str, optional
        The studies to show; by default every study whose folder holds a ``metrics.json``.

    Figures and metrics are read from the same folders, so the page always matches them;
    it replaces the previous page in one step.
    """
    from dmpopt.cli import STUDIES

    out = Path(out_dir)
    if names is None:
        names = [name for name in STUDIES if (out / name / "metrics.json").is_file()]
    sections = []
    for name in names:
        metrics = json.loads((out / name / "metrics.json").read_text())
        figures = sorted((out / name).glob("*.png"))
        images = "\n".join(
            f'<figure><img src="{html.escape(f"{name}/{f.name}")}" alt="{html.escape(f.stem)}">'
            f"<figcaption>{html.escape(f.stem)}</figcaption></figure>"
            for f in figures
        )
        videos = "\n".join(
            f'<figure><img src="{html.escape(f"{name}/{video}")}" alt="{html.escape(video)}">'
            f"<figcaption>{html.escape(video)} (MuJoCo, rendered offscreen)</figcaption></figure>"
            for video in metrics.get("videos") or []
        )
        if metrics.get("videos_skipped"):
            videos += f"<p>videos skipped: {html.escape(str(metrics['videos_skipped']))}</p>"
        shown = {k: v for k, v in metrics.items() if k not in ("versions", "parameters")}
        sections.append(
            f'<section id="{html.escape(name)}"><h2>{html.escape(name)}</h2>'
            f'<pre class="claim">{html.escape(_claim(name))}</pre>{images}{videos}'
            f"<details><summary>metrics</summary><pre>"
            f"{html.escape(json.dumps(shown, indent=2))}</pre></details></section>"
        )
    page = (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        "<title>dmpopt: Learning Movement Primitives, reproduced</title><style>"
        "body{font-family:sans-serif;max-width:1200px;margin:auto;padding:1em}"
        "img{max-width:100%;border:1px solid #ddd}figure{margin:1em 0}"
        "pre{background:#f6f6f6;padding:.6em;overflow-x:auto;white-space:pre-wrap}"
        '</style></head><body><h1>dmpopt: the studies of "Learning Movement Primitives"</h1>'
        + "".join(sections)
        + "</body></html>\n"
    )
    return write_text_atomic(out / "report.html", page)
