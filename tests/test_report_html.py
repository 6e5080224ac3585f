"""report.html: a self-contained page per run, rendered by headless Chromium with every figure loaded."""
import re
import shutil
import subprocess
import tempfile

import numpy as np
import pytest
from PIL import Image

from mechsim.scenarios.loader import load
from mechsim.scenarios.output.writer import write_result
from mechsim.scenarios.runner import run

CHROMIUM = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None)
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]
#: appended to a copy of the page (never to the product): after load, the count of images that decoded
PROBE = ("<script>window.addEventListener('load', () => { const im = [...document.images]; "
         "document.body.setAttribute('data-loaded', im.filter(i => i.complete && i.naturalWidth > 0).length + '/' "
         "+ im.length); });</script>")


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "run"
    sc = load("geneva-lc1", ["duration='1.5 s'", "output_step='2 ms'"])
    write_result(run(sc), out)
    return out


def test_page_is_self_contained_with_every_figure_and_section(report):
    page = (report / "report.html").read_text(encoding="utf-8")
    pngs = sorted(p.stem for p in report.glob("*.png"))
    assert len(pngs) >= 6
    assert sorted(re.findall(r'<img alt="([^"]+)" src="data:image/png;base64,', page)) == pngs
    assert not re.search(r'(src|href)="(?!data:)', page)            # nothing outside the page
    for section in ("Model", "Peaks", "Energy balance (J)", "Events", "Warnings", "Figures", "Scenario (resolved, SI)"):
        assert f"<h2>{section}</h2>" in page
    assert "closed-form" in page and "contact_force_N" in page


def _chromium(*args, timeout=120):
    with tempfile.TemporaryDirectory() as profile:
        return subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *args], capture_output=True,
                              text=True, timeout=timeout)


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium on PATH (Debian: apt-get install -y chromium)")
def test_chromium_renders_the_page_with_every_image_loaded(report, tmp_path):
    page = (report / "report.html").read_text(encoding="utf-8")
    probe = tmp_path / "probe.html"
    probe.write_text(page.replace("</body>", PROBE + "</body>"), encoding="utf-8")
    dom = _chromium("--dump-dom", probe.as_uri()).stdout
    loaded = re.search(r'data-loaded="(\d+)/(\d+)"', dom)
    assert loaded, dom[-500:]
    n_png = len(list(report.glob("*.png")))
    assert loaded.group(1) == loaded.group(2) == str(n_png)
    shot = tmp_path / "shot.png"
    _chromium(f"--screenshot={shot}", "--window-size=1280,2400", (report / "report.html").as_uri())
    pixels = np.asarray(Image.open(shot).convert("L"), float)
    assert pixels.shape == (2400, 1280)
    assert pixels.std() > 10 and (pixels < 128).mean() > 0.005      # text and figures drawn, not a blank page
