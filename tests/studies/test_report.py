"""report.html: summary first, captioned figures, compact collapsed metrics, headless Chromium."""

import json
import re
import shutil
import subprocess
from html.parser import HTMLParser

import numpy as np
import pytest

from dmpopt.exceptions import FileFormatError, InvalidInputError

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
ROW = {
    "claim": "reproduces the ``demo``",
    "paper": "not in the paper",
    "dmpopt": "0.33 mm median",
    "anchor": "LWR 1.9 mm",
    "verdict": "reproduced",
}
CAPTION = "The fits lie on the demonstrations: see ``rmse_mm``."
LONG = 3000  # values of the long list in the fixture's metrics
N_NESTED = 300  # keys of the nested dict: expanded, its table would print on several pages


def _png(path, width=11.0, height=4.0):
    """A figure of a study's usual size (1320 x 480 px), so the printed length is realistic."""
    from dmpopt_studies.common import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(width, height))
    ax.plot(np.sin(np.linspace(0, 10, 200)))
    fig.savefig(path, dpi=120)
    plt.close(fig)


@pytest.fixture
def results(tmp_path):
    """A results folder: imitation with summary, captions, a long list and a nested dict;
    biped as an old run (no summary, no captions) with one figure."""
    (tmp_path / "imitation").mkdir()
    (tmp_path / "biped").mkdir()
    metrics = {
        "study": "imitation",
        "quick": False,
        "versions": {"numpy": "2"},
        "summary": [ROW, {**ROW, "claim": "second claim"}],
        "captions": {"rmse_vs_basis": CAPTION},
        "rmse_mm": {"10": 1.23456, "30": 0.5},
        "trace": list(np.linspace(0.0, 1.0, LONG)),
        "by_case": {f"case_{k}": float(k) for k in range(N_NESTED)},
        "fell": False,
    }
    (tmp_path / "imitation" / "metrics.json").write_text(json.dumps(metrics))
    (tmp_path / "biped" / "metrics.json").write_text(json.dumps({"steps_walked": 148}))
    for path in ("imitation/rmse_vs_basis.png", "imitation/new_goals.png", "biped/joints.png"):
        _png(tmp_path / path)
    return tmp_path


def _write(folder, **kwargs) -> str:
    from dmpopt_studies.report import write_report

    return write_report(folder, **kwargs).read_text()


def test_summary_table_comes_first_with_every_row_and_column(results):
    page = _write(results)
    assert page.index('<table class="summary">') < page.index("<figure")
    table = page[page.index('<table class="summary">') : page.index("</table>")]
    headers = re.findall(r"<th>(.*?)</th>", table)
    assert headers == ["study", "claim", "paper", "dmpopt (measured)", "best anchor", "verdict"]
    assert table.count("<tr>") == 1 + 2 + 1  # header, two imitation rows, biped's note
    assert "second claim" in table and "0.33 mm median" in table
    assert "no summary table" in table.split('href="#biped"')[1]
    assert table.count('rowspan="2"') == 1 and table.count('href="#imitation"') == 1


def test_captions_come_from_the_metrics_and_titles_otherwise(results):
    """Every figure has a caption and an alt text, never its file name."""
    page = _write(results)
    figures = re.findall(r'<figure><img src="([^"]+)" alt="([^"]*)"><figcaption>(.*?)<', page)
    assert [src for src, _, _ in figures] == [
        "imitation/new_goals.png",
        "imitation/rmse_vs_basis.png",
        "biped/joints.png",
    ]
    assert figures[1][1] == "The fits lie on the demonstrations: see rmse_mm."
    assert figures[1][2] == "The fits lie on the demonstrations: see "
    for src, alt, caption in figures:
        stem = src.rsplit("/", 1)[1][: -len(".png")]
        assert alt.strip() and caption.strip()
        assert caption.strip() != stem and alt != stem
    assert figures[0][2] == "New goals (figure without a caption)"


def test_rst_double_back_quotes_and_roles_render_as_code():
    from dmpopt_studies.report import inline_rst, rst_blocks

    text = (
        "the ``walk``, ``step`` of :mod:`dmpopt.control` with :class:`~a.B` and **no** `boom` <x>"
    )
    assert inline_rst(text) == (
        "the <code>walk</code>, <code>step</code> of <code>dmpopt.control</code> with "
        "<code>a.B</code> and <strong>no</strong> <em>boom</em> &lt;x&gt;"
    )
    blocks = rst_blocks("First\nparagraph.\n\n* one\n  wrapped\n* two\n\n.. math:: a = b")
    assert (
        blocks
        == "<p>First paragraph.</p>\n<ul><li>one wrapped</li><li>two</li></ul>\n<pre>a = b</pre>"
    )


def test_docstrings_and_summary_show_no_literal_back_quotes(results):
    page = _write(results)
    assert "``" not in page
    assert "<code>demo</code>" in page  # from the summary row
    assert "<code>rmse_mm</code>" in page  # from the caption


def test_metrics_are_collapsed_flat_and_compact_with_the_raw_file_linked(results):
    """One row per leaf of the metrics (nested keys dotted), the long list on one row."""
    page = _write(results)
    assert "<details open" not in page
    assert '<a href="imitation/metrics.json">metrics.json</a>' in page
    section = page[page.index('<section id="imitation">') : page.index('<section id="biped">')]
    table = section[section.index('<table class="metrics">') :]
    keys = re.findall(r"<tr><td>([^<]*)</td>", table)
    expected = ["quick", "rmse_mm.10", "rmse_mm.30", "trace"]
    expected += [f"by_case.case_{k}" for k in range(N_NESTED)] + ["fell"]
    assert keys == expected
    assert f"<td>{LONG} values: 0, 0.0003334 ... 1 (min 0, max 1)</td>" in table
    assert "<td>1.235</td>" in table
    assert len(page) < 60_000  # the JSON of the long list alone is about 60 kB


def test_short_values_answer_keys():
    from dmpopt_studies.report import _short

    assert _short(0.000123456) == "0.0001235"
    assert _short([1, 2.5, None]) == "[1, 2.5, None]"
    assert _short([{"a": 1}] * 9).startswith("9 items: ")
    assert _short(list(range(10))) == "10 values: 0, 1 ... 9 (min 0, max 9)"
    assert _short(True) == "True" and _short("x" * 500).endswith("...")
    assert len(_short("x" * 500)) == 160


def test_malformed_summaries_are_shown_not_hidden(results):
    path = results / "imitation" / "metrics.json"
    metrics = json.loads(path.read_text())
    metrics["summary"] = [{k: v for k, v in ROW.items() if k != "verdict"}]
    path.write_text(json.dumps(metrics))
    assert '<td class="note">(verdict missing)</td>' in _write(results)
    for malformed in ("reproduced", [], [ROW, "reproduced"]):
        metrics["summary"] = malformed
        path.write_text(json.dumps(metrics))
        assert "metrics[&#x27;summary&#x27;] is not a list of rows" in _write(results)


def test_bad_inputs_are_refused_with_the_argument_named(results, tmp_path):
    with pytest.raises(InvalidInputError, match="out_dir .* is not a folder"):
        _write(tmp_path / "nowhere")
    with pytest.raises(InvalidInputError, match=r"names: no metrics.json for \['rl'\]"):
        _write(results, names=["imitation", "rl"])
    (results / "biped" / "metrics.json").write_text("{not json")
    with pytest.raises(FileFormatError, match="biped/metrics.json is not valid JSON"):
        _write(results)
    (results / "biped" / "metrics.json").write_text("[1, 2]")
    with pytest.raises(FileFormatError, match="holds a list, expected a JSON object"):
        _write(results)


class _Dom(HTMLParser):
    """The order of the elements the checks need, and each figure's alt and caption."""

    def __init__(self):
        super().__init__()
        self.order, self.figures, self.details_open = [], [], []
        self._caption = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "table":
            self.order.append(f"table.{attrs.get('class')}")
        elif tag == "figure":
            self.order.append("figure")
            self.figures.append({"alt": None, "caption": ""})
        elif tag == "img" and self.figures:
            self.figures[-1]["alt"] = attrs.get("alt")
        elif tag == "figcaption":
            self._caption = self.figures[-1]
        elif tag == "details":
            self.details_open.append("open" in attrs)

    def handle_endtag(self, tag):
        if tag == "figcaption":
            self._caption = None

    def handle_data(self, data):
        if self._caption is not None:
            self._caption["caption"] += data


def chromium(page, *options, timeout=120):
    """Run headless Chromium on ``page`` (a path) with ``options``; return its stdout."""
    done = subprocess.run(
        [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            f"--user-data-dir={page.parent / '.chromium-profile'}",
            *options,
            page.as_uri(),
        ],
        check=True,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    return done.stdout


def printed_pages(pdf) -> int:
    """Pages of a PDF written by Chromium: its page objects (``/Type /Page``)."""
    return len(re.findall(rb"/Type\s*/Page(?![s\w])", pdf.read_bytes()))


def test_printed_pages_counts_page_objects_not_the_page_tree(tmp_path):
    pdf = tmp_path / "two.pdf"
    pdf.write_bytes(b"<< /Type /Pages /Count 2 >> << /Type /Page >> << /Type/Page/Parent 1 >>")
    assert printed_pages(pdf) == 2


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (.ci/run installs it)")
def test_report_renders_in_headless_chromium(results):
    """The DOM Chromium builds: the summary table before any figure, every figure with an
    alt text and a caption, every <details> closed; a screenshot that is not blank; printed,
    the page takes a few pages, and expanding the metrics would take more."""
    from matplotlib.image import imread

    page = results / "report.html"
    _write(results)
    dom = _Dom()
    dom.feed(chromium(page, "--dump-dom"))
    assert dom.order[0] == "table.summary" and dom.order.count("figure") == 3
    assert all(f["alt"] and f["caption"].strip() for f in dom.figures)
    assert dom.details_open == [False] * 4
    shot = results / "report.png"
    chromium(page, f"--screenshot={shot}", "--window-size=1000,1400")
    pixels = imread(shot)
    assert pixels.shape[:2] == (1400, 1000) and pixels[..., :3].std() > 0.05  # not blank
    pdf = results / "report.pdf"
    chromium(page, f"--print-to-pdf={pdf}", "--no-pdf-header-footer")
    collapsed = printed_pages(pdf)
    assert 1 <= collapsed <= 3
    page.write_text(page.read_text().replace("<details>", "<details open>"))
    chromium(page, f"--print-to-pdf={pdf}", "--no-pdf-header-footer")
    assert printed_pages(pdf) >= collapsed + 3
