"""report.html: a self-contained page per run, rendered by headless Chromium with every figure loaded."""
import re
import shutil
import subprocess
import tempfile
from html.parser import HTMLParser

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
    for section in ("Model", "Peaks", "Energy balance (J)", "Events", "Warnings", "Figures", "Scenario (resolved, SI)",
                    "Thermal model"):
        assert f"<h2>{section}</h2>" in page
    assert "closed-form" in page and "contact force" in page
    check_sections_are_tables_with_units(page)


class Sections(HTMLParser):
    """The page as {h2 heading: [tables, each a list of rows of cell texts]}, plus the tags it holds."""

    def __init__(self):
        super().__init__()
        self.sections, self.tags, self.current, self.text, self.cell = {}, set(), None, None, None

    def handle_starttag(self, tag, attrs):
        self.tags.add(tag)
        if tag == "h2":
            self.text = []
        elif tag == "table" and self.current is not None:
            self.sections[self.current].append([])
        elif tag == "tr" and self.current is not None and self.sections[self.current]:
            self.sections[self.current][-1].append([])
        elif tag in ("td", "th"):
            self.cell = []

    def handle_endtag(self, tag):
        if tag == "h2":
            self.current = "".join(self.text).strip()
            self.sections[self.current], self.text = [], None
        elif tag in ("td", "th") and self.cell is not None:
            if self.current is not None and self.sections[self.current]:
                self.sections[self.current][-1][-1].append("".join(self.cell).strip())
            self.cell = None

    def handle_data(self, data):
        for buffer in (self.text, self.cell):
            if buffer is not None:
                buffer.append(data)


def check_sections_are_tables_with_units(page: str) -> None:
    """Every section a table (the figures' and an empty warnings list apart), no raw JSON or preformatted dump,
    every number of the summary's sections beside its unit: the tables of quantities have a unit column, filled
    wherever the summary key names a unit."""
    parsed = Sections()
    parsed.feed(page)
    assert "pre" not in parsed.tags and not re.search(r'[{\[]\s*"', page)      # no JSON left on the page
    for heading, tables in parsed.sections.items():
        if heading == "Figures" or (heading == "Warnings" and not tables):
            continue
        assert tables and all(len(t) > 1 for t in tables), heading
    units = {}
    for heading in ("Model", "Peaks", "Energy balance (J)", "Solver", "Scenario (resolved, SI)", "Thermal model"):
        (table,) = parsed.sections[heading]
        header = table[0]
        assert "unit" in header, (heading, header)
        at = header.index("unit")
        pairs = heading in ("Peaks", "Scenario (resolved, SI)")       # rows named by two cells
        units[heading] = {tuple(row[:2]) if pairs else row[0]: row[at] for row in table[1:]}
    assert units["Model"]["geometry: centre distance"] == "m" and units["Model"]["method"] == ""
    assert units["Peaks"][("contact force", "max")] == "N" and units["Peaks"][("wheel accel", "min")] == "rad/s²"
    assert units["Energy balance (J)"]["closure error / the largest energy term"] == "1"
    assert units["Energy balance (J)"]["work: drive"] == "J"
    assert units["Solver"]["wall time"] == "s"
    scenario = units["Scenario (resolved, SI)"]
    assert scenario[("mechanism", "crank_radius")] == "m" and scenario[("load", "wheel_torque")] == "N·m"
    assert scenario[("thermal", "convection_pin")] == "W/(m²·K)" and scenario[("contact", "friction")] == ""
    thermal = units["Thermal model"]
    assert thermal["bodies: pin: capacity"] == "J/K" and thermal["material: conductivity"] == "W/(m·K)"
    assert thermal["heat balance: closure error (relative)"] == "1" and thermal["time constants"] == "s"


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
    check_sections_are_tables_with_units(dom.replace(PROBE, ""))     # the page as the browser built it
    n_png = len(list(report.glob("*.png")))
    assert loaded.group(1) == loaded.group(2) == str(n_png)
    shot = tmp_path / "shot.png"
    _chromium(f"--screenshot={shot}", "--window-size=1280,2400", (report / "report.html").as_uri())
    pixels = np.asarray(Image.open(shot).convert("L"), float)
    assert pixels.shape == (2400, 1280)
    assert pixels.std() > 10 and (pixels < 128).mean() > 0.005      # text and figures drawn, not a blank page
