"""The HTML report of benchmark results: self-contained, escaped, complete, and drawn by a browser."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import matplotlib.pyplot as plt
import pytest
from PIL import Image

from dgse.bench.core import MANIFEST, BenchContext, load_manifests
from dgse.bench.report import format_value, markdown_to_html, write_report
from dgse.cli.main import main
from dgse.errors import InputDataError

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
DATA_PNG = "data:image/png;base64,"


class _Page(HTMLParser):
    """The ``<img>`` and ``<body>`` attributes and the tags of an HTML page."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.imgs: list[dict[str, str | None]] = []
        self.body: dict[str, str | None] = {}
        self.tags: list[str] = []
        self.feed(text)
        self.close()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        if tag == "img":
            self.imgs.append(dict(attrs))
        elif tag == "body":
            self.body = dict(attrs)


def _figure(kind: str = "line"):
    fig, ax = plt.subplots(figsize=(2.4, 1.6))
    if kind == "line":
        ax.plot([5, 50, 300], [0.4, 0.2, 0.1], marker="o")
    else:
        ax.bar(["a", "b"], [1.0, 2.0])
    ax.set_xlabel("observations")
    return fig


@pytest.fixture
def results(tmp_path: Path) -> Path:
    """Two suites written through BenchContext (one with figures and tables, one with text only)."""
    root = tmp_path / "results"
    ctx = BenchContext(
        "variants",
        root,
        quick=True,
        seed=3,
        command="dgse bench variants --quick --out results",
        title="DGSE variants (fig5)",
        description="DGSE-O, DGSE-P and DGSE-S over `5` to **300** observations.",
    )
    sec = ctx.section(
        "Errors against observations",
        "The RMSE falls with more observations.\n\n- wind & concentration\n- source <error>",
    )
    sec.figure(_figure(), "rmse", "RMSE over observations <b>not bold</b>")
    sec.table(
        "rmse",
        [
            {"method": "DGSE-S", "n": 50, "rmse": 0.123456789},
            {"method": "DGSE-O", "n": 300, "rmse": None},
        ],
        caption="RMSE table <b>raw</b> & more",
    )
    sec2 = ctx.section("Cross-entropy")
    sec2.figure(_figure("bar"), "ce", "Cross-entropy of the source posterior")
    ctx.note("2 layout(s) skipped: the solver did not converge")
    ctx.finish()

    cal = BenchContext(
        "calibration",
        root,
        command="dgse bench calibration --out results",
        title="Calibration",
        description="Text only.",
    )
    cal.section("Nothing drawn", "Only **text** here.")
    cal.finish()
    return root


def _report(results: Path) -> tuple[str, _Page]:
    path = write_report(results)
    assert path == results / "report.html"
    text = path.read_text(encoding="utf-8")
    return text, _Page(text)


def test_every_figure_is_embedded_as_the_same_png(results: Path) -> None:
    text, page = _report(results)
    manifests = load_manifests(results)
    expected = [
        (Path(m["_dir"]) / f["file"]).read_bytes()
        for m in manifests
        for s in m["sections"]
        for f in s["figures"]
    ]
    assert len(expected) == 2
    assert len(page.imgs) == len(expected)
    embedded = []
    for img in page.imgs:
        src = img["src"] or ""
        assert src.startswith(DATA_PNG)
        data = base64.b64decode(src[len(DATA_PNG) :], validate=True)
        assert data.startswith(PNG_MAGIC)
        Image.open(io.BytesIO(data)).verify()
        embedded.append(data)
    assert sorted(embedded) == sorted(expected)
    for m in manifests:
        for s in m["sections"]:
            for f in s["figures"]:
                caption = f["caption"].replace("<", "&lt;").replace(">", "&gt;")
                assert caption in text


def test_tables_text_and_provenance(results: Path) -> None:
    text, _ = _report(results)
    assert "RMSE table &lt;b&gt;raw&lt;/b&gt; &amp; more" in text
    assert "<b>raw</b>" not in text and "<b>not bold</b>" not in text
    assert "0.1235" in text  # 4 significant digits
    assert "0.123456789" not in text
    assert "DGSE-S" in text and "DGSE-O" in text
    assert '<th class="num">rmse</th>' in text
    # section text as Markdown, escaped
    assert "<li>source &lt;error&gt;</li>" in text
    assert "<li>wind &amp; concentration</li>" in text
    assert "<strong>text</strong>" in text
    assert "<code>5</code>" in text and "<strong>300</strong>" in text
    # per suite: command, notes, versions; both suites in the order of `dgse bench all`
    assert "dgse bench variants --quick --out results" in text
    assert "2 layout(s) skipped" in text
    assert "numpy" in text and "Python" in text
    assert text.index("DGSE variants (fig5)") < text.index("Calibration")
    assert "Nothing drawn" in text


def test_self_contained_and_link_free(results: Path) -> None:
    text, page = _report(results)
    assert not re.search(r"""(src|href)\s*=\s*(?!["']?data:)""", text, flags=re.IGNORECASE)
    assert "http://" not in text and "https://" not in text
    assert "a" not in page.tags and "link" not in page.tags
    assert 'window.addEventListener("load"' in text


def test_summary_is_rendered_first(results: Path) -> None:
    (results / "summary.md").write_text(
        "# Summary\n\nDGSE-S wins **most** benchmarks.\n\n## Caveats\n\n- quick run <small>\n- `K=8`\n"
    )
    text = write_report(results, summary=False).read_text(encoding="utf-8")  # the one that is there
    assert "<h2>Summary</h2>" in text and "<h3>Caveats</h3>" in text
    assert "<li>quick run &lt;small&gt;</li>" in text and "<li><code>K=8</code></li>" in text
    assert text.index("<h2>Summary</h2>") < text.index("DGSE variants (fig5)")


def test_hand_written_manifest_without_figures_or_sections(tmp_path: Path) -> None:
    d = tmp_path / "res" / "custom"
    d.mkdir(parents=True)
    manifest = {"format": "dgse-bench-suite", "suite": "custom", "title": "Custom <suite>", "sections": []}
    (d / MANIFEST).write_text(json.dumps(manifest))
    (tmp_path / "res" / "gsl").mkdir()  # an interrupted suite: no manifest
    out = write_report(tmp_path / "res", tmp_path / "out" / "page.html")
    text = out.read_text()
    assert "Custom &lt;suite&gt;" in text and "<img" not in text
    assert "Suites without results" in text and "<code>gsl</code>" in text


def test_missing_figure_file_is_reported_not_broken(results: Path) -> None:
    (results / "variants" / "ce.png").unlink()
    text, page = _report(results)
    assert len(page.imgs) == 1
    assert "Figure file missing" in text and "variants/ce.png" in text


def test_bad_directories_are_input_errors(tmp_path: Path) -> None:
    with pytest.raises(InputDataError, match="no such results directory"):
        write_report(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputDataError, match="no suite results"):
        write_report(tmp_path / "empty")
    (tmp_path / "file.txt").write_text("x")
    with pytest.raises(InputDataError, match="not a directory"):
        write_report(tmp_path / "file.txt")
    (tmp_path / "bad" / "gdm").mkdir(parents=True)
    (tmp_path / "bad" / "gdm" / MANIFEST).write_text("{not json")
    with pytest.raises(InputDataError, match="cannot be read"):
        write_report(tmp_path / "bad")


def test_markdown_subset() -> None:
    got = markdown_to_html("a <b>\nb\n\n- x **y**\n- `<z>` **`k`**\n\ntail")
    assert got == (
        "<p>a &lt;b&gt;\nb</p>\n"
        "<ul><li>x <strong>y</strong></li>"
        "<li><code>&lt;z&gt;</code> <strong><code>k</code></strong></li></ul>\n"
        "<p>tail</p>"
    )
    assert markdown_to_html("`**a**`") == "<p><code>**a**</code></p>"
    assert markdown_to_html("# T") == "<p># T</p>"
    assert markdown_to_html("# T\n## U", heading_level=2) == "<h2>T</h2>\n<h3>U</h3>"
    assert markdown_to_html("1. one\n2. two") == "<ol><li>one</li><li>two</li></ol>"
    assert "<pre><code>x &lt; 1</code></pre>" in markdown_to_html("```\nx < 1\n```")
    table = markdown_to_html("| a | b |\n|---|--:|\n| 1 | <2> |")
    assert "<th>a</th>" in table and '<td style="text-align:right">&lt;2&gt;</td>' in table


def test_format_value() -> None:
    assert format_value(0.123456789) == "0.1235"
    assert format_value(12.3456) == "12.35"
    assert format_value(-3.0) == "-3"
    assert format_value(123456.7) == "123,457"
    assert format_value(7) == "7"
    assert format_value(None) == "\u2013"
    assert format_value(True) == "yes"
    assert format_value("<x>") == "&lt;x&gt;"
    assert "10<sup>-5</sup>" in format_value(1.5e-5)


def test_cli_report(results: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["report", str(results)]) == 0
    assert (results / "report.html").is_file()
    out = tmp_path / "elsewhere" / "r.html"
    assert main(["report", str(results), "-o", str(out)]) == 0
    assert out.is_file() and "<img" in out.read_text()
    capsys.readouterr()
    assert main(["report", str(tmp_path / "missing")]) == 2
    err = capsys.readouterr().err
    assert "error:" in err and "Traceback" not in err


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "headless_shell"):
        found = shutil.which(name)
        if found:
            return found
    return None


def test_report_renders_in_a_headless_browser(results: Path, tmp_path: Path) -> None:
    browser = _chromium()
    if browser is None:
        pytest.skip("no Chromium on the PATH (chromium, chromium-browser, google-chrome, headless_shell)")
    report = write_report(results)
    common = [
        browser,
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--no-first-run",
        "--virtual-time-budget=10000",
    ]

    def run(*args: str, profile: str) -> subprocess.CompletedProcess[str]:
        cmd = [*common, f"--user-data-dir={tmp_path / profile}", *args, report.as_uri()]
        return subprocess.run(cmd, capture_output=True, text=True, timeout=60, check=False)

    dom = run("--dump-dom", profile="profile-dom")
    assert dom.returncode == 0, dom.stderr[-2000:]
    page = _Page(dom.stdout)
    assert page.body.get("data-images-checked") == "1", dom.stdout[-2000:]
    assert len(page.imgs) == 2
    assert all(img.get("data-rendered") == "1" for img in page.imgs), [
        img.get("data-rendered") for img in page.imgs
    ]

    shot = tmp_path / "report.png"
    res = run(f"--screenshot={shot}", "--window-size=1280,1600", "--hide-scrollbars", profile="profile-shot")
    assert res.returncode == 0, res.stderr[-2000:]
    assert shot.is_file() and shot.stat().st_size > 10_000
    with Image.open(shot) as im:
        assert im.size == (1280, 1600)
        colors = im.convert("RGB").getcolors(maxcolors=1 << 20)
        assert colors is None or len(colors) > 50  # not a blank page
