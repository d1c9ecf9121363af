"""Open a page in headless Chromium and read back what it shows: a probe script added to a
copy of the page writes, once the page has loaded, each image's size as loaded, each compared
image's verdicts and each figure's key into the DOM, which ``chromium --headless --dump-dom``
prints. Tests that need it skip, naming the browser, where Debian's ``chromium`` (or Google
Chrome) is not installed."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
TIMEOUT_S = 120  # a cold start of Chromium on a busy machine takes a few seconds

PROBE = """
<script>
window.addEventListener('load', function () {
  var out = {images: [], sections: [], figures: []};
  document.querySelectorAll('img').forEach(function (i) {
    out.images.push({alt: i.alt, loaded: i.complete && i.naturalWidth > 0,
                     width: i.naturalWidth, height: i.naturalHeight,
                     inline: i.src.indexOf('data:image/png;base64,') === 0});
  });
  document.querySelectorAll('section.image').forEach(function (s) {
    var groups = {};
    s.querySelectorAll('tr[data-group]').forEach(function (r) {
      groups[r.dataset.group] = r.dataset.verdict; });
    out.sections.push({name: s.dataset.name, verdict: s.dataset.verdict, groups: groups,
                       heading: s.querySelector('h2').textContent});
  });
  document.querySelectorAll('figure').forEach(function (f) {
    var key = f.querySelector('.key');
    out.figures.push({alts: Array.from(f.querySelectorAll('img')).map(function (i) {
                        return i.alt; }),
                      key: key ? key.className : null, key_text: key ? key.textContent : '',
                      caption: f.querySelector('figcaption').textContent});
  });
  var pre = document.createElement('pre');
  pre.id = 'probe';
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>
"""


def browser() -> str:
    """The path of a Chromium; skips the test naming the browser when there is none."""
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("headless Chromium is not installed (Debian: apt-get install chromium); "
                f"looked for {', '.join(BROWSERS)}")


def read_page(page: Path, tmp_path: Path) -> dict:
    """What Chromium shows of ``page``: {"images": [...], "sections": [...], "figures": [...]}
    (see PROBE)."""
    exe = browser()
    text = page.read_text(encoding="utf-8")
    assert "</body>" in text
    probe = tmp_path / ("probe-" + page.name)
    probe.write_text(text.replace("</body>", PROBE + "</body>"), encoding="utf-8")
    run = subprocess.run(
        [exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--disable-extensions", "--virtual-time-budget=10000",
         f"--user-data-dir={tmp_path / 'chromium-profile'}", "--dump-dom", probe.as_uri()],
        capture_output=True, text=True, timeout=TIMEOUT_S)
    m = re.search(r'<pre id="probe">(.*?)</pre>', run.stdout, re.S)
    assert m, f"{exe} printed no probe (exit {run.returncode}): {run.stderr[-2000:]}"
    import html

    return json.loads(html.unescape(m.group(1)))


def assert_offline(page: Path) -> None:
    """The page fetches nothing: no script, style or image from elsewhere."""
    text = page.read_text(encoding="utf-8")
    assert not re.search(r'\b(src|href)="(?!data:|#)', text), "a resource outside the page"
    assert "<link" not in text and "@import" not in text and "url(" not in text
