"""One short HTML page: every study's summary table first, then its figures with captions.

Each study's ``metrics.json`` may hold ``"summary"`` (rows with the keys of :data:`COLUMNS`)
and ``"captions"`` (figure stem -> what to see in it); results written before they existed
still render, with a note instead of the table and a title instead of the caption. The
metrics are collapsed by default and shown as a flat table of short values; long lists are
summarised and the raw ``metrics.json`` is linked.
"""

from __future__ import annotations

import html
import importlib
import json
import re
from pathlib import Path

from dmpopt.exceptions import FileFormatError, InvalidInputError

from .common import write_text_atomic
from .registry import STUDIES

COLUMNS = {
    "claim": "claim",
    "paper": "paper",
    "dmpopt": "dmpopt (measured)",
    "anchor": "best anchor",
    "verdict": "verdict",
}
HIDDEN = ("study", "versions", "parameters", "summary", "captions", "videos", "videos_skipped")
SHORT_LIST = 6  # lists up to this many short values are shown in full
SHORT_TEXT = 160  # [characters] longer values are cut
STYLE = """
body{font-family:system-ui,sans-serif;max-width:1000px;margin:auto;padding:0 1em;
  line-height:1.4;color:#222}
h1{font-size:1.6em}h2{margin-top:2em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;width:100%;font-size:.9em;margin:.5em 0}
th,td{border:1px solid #ddd;padding:.25em .45em;text-align:left;vertical-align:top}
th{background:#f2f2f2}td.study{font-weight:bold;white-space:nowrap}
table.metrics td:first-child{font-family:monospace;word-break:break-all;width:40%}
figure{margin:1em 0;break-inside:avoid}img{max-width:100%;border:1px solid #eee}
figcaption{font-size:.92em;color:#333;margin-top:.3em}
code{background:#f4f4f4;padding:0 .2em;font-size:.92em}
pre{background:#f6f6f6;padding:.5em;white-space:pre-wrap}
details{margin:.6em 0}summary{cursor:pointer;color:#035}
.note{color:#666;font-style:italic}
@media print{body{max-width:none;font-size:10pt}img{max-height:11cm;width:auto}
  h2{break-before:auto;break-after:avoid}table{break-inside:auto}tr{break-inside:avoid}}
"""


def inline_rst(text: str) -> str:
    """Escape ``text`` for HTML and render its inline reStructuredText as HTML.

    Double back-quotes and roles (``:mod:`x```, ``:math:`x```) become ``<code>``, single
    back-quotes ``<em>``, ``**x**`` ``<strong>``.
    """
    out = html.escape(str(text), quote=False)
    out = re.sub(r"``(.+?)``", r"<code>\1</code>", out)
    out = re.sub(r":[a-z]+:`~?([^`]+)`", r"<code>\1</code>", out)
    out = re.sub(r"`([^`<]+)`_?", r"<em>\1</em>", out)
    return re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", out)


def _plain(text) -> str:
    """``text`` without its inline markup, escaped for an HTML attribute (an alt text)."""
    return re.sub(r"<[^>]+>", "", inline_rst(" ".join(str(text).split()))).replace('"', "&quot;")


def rst_blocks(text: str) -> str:
    """Paragraphs, bullet lists and ``.. math::`` blocks of a docstring as HTML."""
    parts = []
    for block in re.split(r"\n\s*\n", text.strip()):
        lines = block.splitlines()
        if lines[0].lstrip().startswith(".. math::"):
            parts.append(f"<pre>{html.escape(block.split('::', 1)[1].strip())}</pre>")
        elif lines[0].lstrip().startswith(("* ", "- ")):
            items = re.split(r"\n\s*[*-] ", "\n" + block.strip())[1:]
            rows = "".join(f"<li>{inline_rst(' '.join(i.split()))}</li>" for i in items)
            parts.append(f"<ul>{rows}</ul>")
        else:
            parts.append(f"<p>{inline_rst(' '.join(block.split()))}</p>")
    return "\n".join(parts)


def _docstring(name: str) -> tuple[str, str]:
    """The study module's title line and the rest of its docstring."""
    try:
        doc = importlib.import_module(f"dmpopt_studies.{name}").__doc__ or ""
    except ImportError:
        doc = ""
    title, _, rest = doc.strip().partition("\n")
    return title.strip() or name, rest


def figure_title(stem: str) -> str:
    """A readable title from a figure's file stem (``rl_curves_six_dof`` -> "Rl curves six
    dof"), the fallback when a study gives no caption."""
    words = stem.replace("_", " ").replace("-", " ").strip()
    return f"{words[:1].upper()}{words[1:]} (figure without a caption)"


def _short(value) -> str:
    """One table cell for a metric value: numbers to 4 significant digits, long lists
    summarised, any text cut at :data:`SHORT_TEXT` characters."""
    if isinstance(value, float):
        text = f"{value:.4g}"
    elif isinstance(value, list):
        text = _short_list(value)
    else:
        text = str(value)
    return text if len(text) <= SHORT_TEXT else text[: SHORT_TEXT - 3] + "..."


def _short_list(value: list) -> str:
    scalars = all(isinstance(v, (int, float, str, bool)) or v is None for v in value)
    if scalars and len(value) <= SHORT_LIST:
        return "[" + ", ".join(_short(v) for v in value) + "]"
    numbers = [v for v in value if isinstance(v, (int, float)) and not isinstance(v, bool)]
    if numbers and len(numbers) == len(value):
        return (
            f"{len(value)} values: {_short(value[0])}, {_short(value[1])} ... "
            f"{_short(value[-1])} (min {_short(min(numbers))}, max {_short(max(numbers))})"
        )
    return f"{len(value)} items: {_short(value[0])}, ... (in metrics.json)"


def flat_metrics(metrics: dict, prefix: str = "") -> list[tuple[str, str]]:
    """(dotted key, short value) rows of ``metrics``; nested dicts are flattened, lists
    summarised (:func:`_short`); the keys in :data:`HIDDEN` are left out at the top level."""
    rows = []
    for key, value in metrics.items():
        if not prefix and key in HIDDEN:
            continue
        name = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            rows.extend(flat_metrics(value, f"{name}."))
        else:
            rows.append((name, _short(value)))
    return rows


def _summary_rows(name: str, metrics: dict) -> list[str]:
    """The study's rows of the summary table (a note when it has none or a malformed one)."""
    link = f'<a href="#{html.escape(name)}">{html.escape(name)}</a>'
    rows = metrics.get("summary")
    if rows is None:
        note = "no summary table in this study's metrics.json (written before it had one)"
    elif not rows or not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        note = html.escape(f"metrics['summary'] is not a list of rows (dicts): {_short(rows)}")
    else:
        note = None
    if note is not None:
        return [f'<tr><td class="study">{link}</td><td colspan="5" class="note">{note}</td></tr>']
    cells = []
    for k, row in enumerate(rows):
        study = f'<td class="study" rowspan="{len(rows)}">{link}</td>' if k == 0 else ""
        cell = "".join(
            f"<td>{inline_rst(row[key])}</td>"
            if key in row
            else f'<td class="note">({key} missing)</td>'
            for key in COLUMNS
        )
        cells.append(f"<tr>{study}{cell}</tr>")
    return cells


def _figures(out: Path, name: str, metrics: dict) -> str:
    captions = metrics.get("captions")
    captions = captions if isinstance(captions, dict) else {}
    parts = []
    for path in sorted((out / name).glob("*.png")):
        caption = captions.get(path.stem) or figure_title(path.stem)
        alt = _plain(caption)
        parts.append(
            f'<figure><img src="{html.escape(f"{name}/{path.name}")}" alt="{alt}">'
            f"<figcaption>{inline_rst(caption)}</figcaption></figure>"
        )
    for video in metrics.get("videos") or []:
        stem = Path(video).stem
        caption = captions.get(stem) or figure_title(stem)
        parts.append(
            f'<figure class="video"><img src="{html.escape(f"{name}/{video}")}" '
            f'alt="{_plain(caption)}"><figcaption>{inline_rst(caption)} '
            "(animation, MuJoCo rendered offscreen)</figcaption></figure>"
        )
    if metrics.get("videos_skipped"):
        skipped = html.escape(str(metrics["videos_skipped"]))
        parts.append(f'<p class="note">videos skipped: {skipped}</p>')
    return "\n".join(parts)


def _section(out: Path, name: str, metrics: dict) -> str:
    title, setup = _docstring(name)
    rows = [
        f"<tr><td>{html.escape(key)}</td><td>{html.escape(value)}</td></tr>"
        for key, value in flat_metrics(metrics)
    ]
    quick = " (quick run)" if metrics.get("quick") else ""
    return (
        f'<section id="{html.escape(name)}"><h2>{inline_rst(title)}</h2>'
        f"{_figures(out, name, metrics)}"
        f"<details><summary>claim and set-up</summary>{rst_blocks(setup)}</details>"
        f"<details><summary>metrics{quick}: {len(rows)} values "
        f'(raw: <a href="{html.escape(name)}/metrics.json">metrics.json</a>)</summary>'
        f'<table class="metrics">{"".join(rows)}</table></details></section>'
    )


def _read_metrics(path: Path) -> dict:
    try:
        metrics = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise FileFormatError(
            f"{path} is not valid JSON ({error}); rerun the study to rewrite it"
        ) from error
    if not isinstance(metrics, dict):
        raise FileFormatError(
            f"{path} holds a {type(metrics).__name__}, expected a JSON object; rerun the study"
        )
    return metrics


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
    out = Path(out_dir)
    if not out.is_dir():
        raise InvalidInputError(f"out_dir {str(out)!r} is not a folder; pass the results folder")
    if names is None:
        names = [name for name in STUDIES if (out / name / "metrics.json").is_file()]
    missing = [name for name in names if not (out / name / "metrics.json").is_file()]
    if missing:
        raise InvalidInputError(
            f"names: no metrics.json for {missing} in {out}; run those studies first or leave "
            "them out"
        )
    studies = {name: _read_metrics(out / name / "metrics.json") for name in names}
    summary = "".join(
        row for name, metrics in studies.items() for row in _summary_rows(name, metrics)
    )
    header = "".join(f"<th>{label}</th>" for label in ("study", *COLUMNS.values()))
    page = (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        "<title>dmpopt: Learning Movement Primitives, reproduced</title>"
        f"<style>{STYLE}</style></head><body>"
        '<h1>dmpopt: the studies of "Learning Movement Primitives" (Schaal et al. 2003)</h1>'
        '<section id="summary"><h2>Summary</h2><p>Each row: a claim, what the paper states, '
        "what dmpopt measured in this run, the best other method measured on the same cases, "
        "and the verdict. The sections below show the figures; each section's metrics are "
        "collapsed under its figures.</p>"
        f'<table class="summary"><thead><tr>{header}</tr></thead><tbody>{summary}</tbody>'
        "</table></section>"
        + "".join(_section(out, name, metrics) for name, metrics in studies.items())
        + "</body></html>\n"
    )
    return write_text_atomic(out / "report.html", page)
