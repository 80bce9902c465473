"""The post-well report as a browser shows it: headless Chromium renders the page of a real
recording once, takes a screenshot and hands back the page after a script measured it.

Chromium is installed by the project's set-up (``scripts/test.sh``, as mosquitto is); the test
fails, not skips, without it.
"""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path
from typing import Any

from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import RecordedMessage
from tdmon.record.report import write_report

# Run in the page after it loaded: what a reader sees, as JSON in <pre id="structure">.
_MEASURE = """
<script>
window.addEventListener("load", () => {
  const visible = (e) => {
    const r = e.getBoundingClientRect();
    return r.width > 0 && r.height > 0;
  };
  const text = (e) => (e ? e.textContent.trim() : "");
  const tables = [...document.querySelectorAll("table")].map((t) => ({
    body_rows: t.querySelectorAll("tbody tr, tr:not(thead tr)").length,
    empty_header_rows: [...t.querySelectorAll("thead tr")]
      .filter((r) => [...r.cells].every((c) => text(c) === "")).length,
    empty_cells: [...t.querySelectorAll("td")].filter((c) => text(c) === "").length,
  }));
  const images = [...document.querySelectorAll("figure img")].map((i) => ({
    loaded: i.complete && i.naturalWidth > 0, visible: visible(i),
    inside: i.getBoundingClientRect().right <= document.documentElement.clientWidth,
  }));
  const captions = [...document.querySelectorAll("figcaption")].map(text);
  // every figure heading is followed by its image or by the note saying why there is none
  const figures = [...document.querySelectorAll("h2")].find((h) => text(h).startsWith("Figures"));
  const headings = [];
  for (let e = figures.nextElementSibling; e && e.tagName !== "H2"; e = e.nextElementSibling) {
    if (e.tagName === "FIGURE") {
      headings.push({title: text(e.querySelector("h3")), shown: "figure"});
    } else if (e.tagName === "H3") {
      const next = e.nextElementSibling;
      headings.push({title: text(e), shown: next && next.classList.contains("note") && text(next)
                     ? "note" : "nothing"});
    }
  }
  const headline = document.getElementById("headline");
  const out = document.createElement("pre");
  out.id = "structure";
  out.textContent = JSON.stringify({
    tables, images, captions, headings,
    headline: headline && visible(headline) ? text(headline) : "",
    headline_top: headline ? headline.getBoundingClientRect().top : null,
  });
  document.body.appendChild(out);
});
</script>
"""


def _render(chromium: str, page: Path, screenshot: Path, profile: Path) -> dict[str, Any]:
    """One browser start: the screenshot and the measured page."""
    measured = page.with_name("measured.html")
    measured.write_text(page.read_text().replace("</body>", _MEASURE + "</body>"))
    result = subprocess.run(
        [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
         "--no-first-run", f"--user-data-dir={profile}", "--window-size=1100,3000",
         f"--screenshot={screenshot}", "--dump-dom", "--virtual-time-budget=5000",
         measured.as_uri()],
        capture_output=True, text=True, timeout=120, check=False)
    found = re.search(r'<pre id="structure">(.*?)</pre>', result.stdout, re.S)
    assert found, f"no measured page from Chromium ({result.returncode}): {result.stderr[-2000:]}"
    return dict(json.loads(found.group(1).replace("&amp;", "&").replace("&lt;", "<")
                           .replace("&gt;", ">").replace("&quot;", '"')))


def test_the_report_as_a_browser_renders_it(tmp_path: Path, stream: list[RecordedMessage],
                                            chromium: str) -> None:
    with McapRecorder(tmp_path / "rec") as recorder:
        for item in stream:
            recorder.write(*item)
    report = write_report(recorder.stats.files, tmp_path / "report", title="Synthetic trip")
    screenshot = tmp_path / "report.png"
    page = _render(chromium, report.html, screenshot, tmp_path / "chromium-profile")

    # the headline first, saying what was found against the plan (the synthetic well file
    # plans no friction, and says so)
    assert page["headline"].startswith("Pick-up friction 0.2")
    assert "the well file plans no friction there" in page["headline"]
    assert page["headline_top"] < 200  # right under the title, in the first screen
    # no empty table, no empty header row, no empty cell
    assert page["tables"] and all(t["body_rows"] > 0 for t in page["tables"]), page["tables"]
    assert sum(t["empty_header_rows"] for t in page["tables"]) == 0
    assert sum(t["empty_cells"] for t in page["tables"]) == 0
    # every figure drawn and inside the page, or explained; numbers without gaps
    # (a trip recording: the torque figure and the drilling page are notes saying why)
    assert [h["shown"] for h in page["headings"]] == [
        "figure", "note", "figure", "figure", "figure", "note"], page["headings"]
    assert page["headings"][1]["title"] == "Surface torque against bit depth"
    assert page["headings"][5]["title"].startswith("Drilling")
    assert len(page["images"]) == 4
    assert all(i["loaded"] and i["visible"] and i["inside"] for i in page["images"])
    assert [c.split(".")[0] for c in page["captions"]] == [f"Figure {n}" for n in range(1, 5)]
    # the screenshot shows the page: the headline's box and border in their colours
    from PIL import Image

    with Image.open(screenshot) as image:
        assert image.size == (1100, 3000)
        colours = {colour for _, colour in image.convert("RGB").getcolors(1 << 24) or []}
    assert (0x33, 0x66, 0x99) in colours and (0xF4, 0xF6, 0xFA) in colours
