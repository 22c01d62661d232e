"""The review report in a real browser: Debian's headless Chromium driven by playwright.

For each report (a bank fault run, a comparison of two runs, a crashed run repaired by the review,
a diverged run, an interrupted run) the page is opened from its ``file://`` URL with the network
blocked (``context.route``) and every request recorded; it must make no request that is not
``file:``/``data:``/``blob:``/``about:``, log no console error and raise no page error; every
figure listed in ``<meta name="fdi-sim-figures">`` must become a plotly plot with traces drawn.
A full-page screenshot is then checked (saved under ``tmp_path``; a failure names the file):
not blank (pixel spread), each figure's box inked, each figure's plot area holding its traces'
line colours, a plausible page height. A zoom (``Plotly.relayout`` of the statistic figure's
x range) must leave points drawn. Issue 15, browser bar.

Chromium comes from Debian (``make browser``: ``apt-get install -y chromium``); without
``/usr/bin/chromium`` the module skips saying how to install it. ``playwright install`` is never used.
"""
from __future__ import annotations

import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

CHROMIUM = Path("/usr/bin/chromium")
pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason=f"{CHROMIUM} not found: the browser tests need Debian's chromium "
           "(`make browser` as root, or `sudo apt-get install -y chromium`)")

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic"]
LOCAL_SCHEMES = ("file:", "data:", "blob:", "about:")
VIEWPORT = {"width": 1280, "height": 900}
RENDER_TIMEOUT_MS = 60_000
#: which review_logs entries each report reads, and what its text must say happened
REPORTS: dict[str, tuple[tuple[str, ...], str | None]] = {
    "fault": (("fault",), None),
    "comparison": (("fault", "fault_b"), None),
    "crashed": (("unrepaired",), "repaired"),
    "diverged": (("diverged",), "diverged"),
    "interrupted": (("interrupted",), "interrupted"),
}
#: a pixel is ink when its darkest channel is below this (plotly's #eeeeee grid is not ink)
INK_BELOW = 215
#: a pixel has a trace's colour when every channel is within this of it
COLOUR_TOLERANCE = 40
#: pixels within this of white in every channel are background (white, the #eeeeee grid)
NEAR_WHITE = 20
#: a line trace is expected on the screenshot when this many of its points lie inside its axes: two
#: make a segment (the timeline's fault and alarm bars are segments of two points each; a run cut off
#: soon after its fault onset has nothing else on its timeline)
MIN_VISIBLE_POINTS = 2

# the state of each figure after rendering: its box on the page, its subplot areas, what it drew,
# and per line trace (plotly's resolved _fullData) its colour, opacity and points inside the axes' ranges
_FIGURE_STATE_JS = """ids => ids.map(id => {
  const el = document.getElementById(id);
  if (!el) return {id, missing: true};
  const box = r => ({x: r.left + window.scrollX, y: r.top + window.scrollY, w: r.width, h: r.height});
  const fl = el._fullLayout || {};
  const axis = (ref, k) => fl[k + 'axis' + ref.slice(1)];
  const inside = (v, a) => { const lo = Math.min(a.range[0], a.range[1]), hi = Math.max(a.range[0], a.range[1]);
                             return v >= lo && v <= hi; };
  const lines = (el._fullData || []).filter(t => t.visible === true && String(t.mode || '').includes('lines')
                                              && t.line && t.line.color && (t.line.width === undefined || t.line.width > 0));
  return {id, missing: false, plotly: el.classList.contains('js-plotly-plot'),
          svg: el.querySelectorAll('.main-svg').length,
          drawn: el.querySelectorAll('.trace').length + el.querySelectorAll('path.js-line').length,
          traces: (el.data || []).length, text: el.textContent,
          box: box(el.getBoundingClientRect()),
          areas: [...el.querySelectorAll('.bglayer rect.bg, .bglayer .bg')].map(r => box(r.getBoundingClientRect())),
          colours: lines.map(t => {
            const xa = axis(t.xaxis || 'x', 'x'), ya = axis(t.yaxis || 'y', 'y'); let n = 0;
            const xs = t.x || [], ys = t.y || [];
            for (let i = 0; i < xs.length; i++) {
              const x = xs[i], y = ys[i];
              if (x === null || x === undefined || y === null || y === undefined) continue;
              if (typeof x === 'number' && xa && xa.range && !inside(x, xa)) continue;
              if (typeof y === 'number' && ya && ya.type !== 'category' && ya.range && !inside(y, ya)) continue;
              n++;
            }
            return [t.line.color, t.opacity === undefined ? 1 : t.opacity, n]; }),
          // on-screen length [px] of each drawn line inside its subplot (SVG coordinates are relative
          // to the subplot: 0..axis._length), by colour and opacity
          lengths: [...el.querySelectorAll('.scatterlayer .trace')].flatMap(g => {
            const cd = g.__data__; const t = cd && cd[0] && cd[0].trace;
            if (!t || !t.line || !t.line.color) return [];
            const xa = axis(t.xaxis || 'x', 'x'), ya = axis(t.yaxis || 'y', 'y'); let len = 0;
            for (const p of g.querySelectorAll('path.js-line')) {
              const v = ((p.getAttribute('d') || '').match(/-?[0-9.]+(?:e-?[0-9]+)?/g) || []).map(Number);
              const ok = (x, y) => x >= 0 && x <= xa._length && y >= 0 && y <= ya._length;
              for (let i = 2; i + 1 < v.length; i += 2)
                if (ok(v[i - 2], v[i - 1]) && ok(v[i], v[i + 1])) len += Math.hypot(v[i] - v[i - 2], v[i + 1] - v[i - 1]); }
            return [[t.line.color, t.opacity === undefined ? 1 : t.opacity, len]]; })};
})"""
# drawn: a plotly plot with traces, or a figure without data that says so ("(no faults, no detectors)")
_ALL_DRAWN_JS = """ids => ids.every(id => { const el = document.getElementById(id);
  return el && el.classList.contains('js-plotly-plot') && el.querySelector('.main-svg')
         && (el.querySelectorAll('.trace, path.js-line').length > 0
             || ((el.data || []).length === 0 && /\\(no [^)]*\\)/.test(el.textContent))); })"""
# vertices of the drawn lines of a figure that fall inside their subplot (SVG coordinates are
# relative to the subplot: 0..axis._length); plotly keeps out-of-view vertices, clipped
_DRAWN_POINTS_JS = """id => { const el = document.getElementById(id); const fl = el._fullLayout; let n = 0;
  for (const g of el.querySelectorAll('.scatterlayer .trace')) {
    const cd = g.__data__; const t = cd && cd[0] && cd[0].trace; if (!t) continue;
    const xa = fl['xaxis' + (t.xaxis || 'x').slice(1)], ya = fl['yaxis' + (t.yaxis || 'y').slice(1)];
    for (const p of g.querySelectorAll('path.js-line')) {
      const v = (p.getAttribute('d') || '').match(/-?[0-9.]+(?:e-?[0-9]+)?/g) || [];
      for (let i = 0; i + 1 < v.length; i += 2) {
        const x = +v[i], y = +v[i + 1];
        if (x >= 0 && x <= xa._length && y >= 0 && y <= ya._length) n++; } } }
  return n; }"""


@dataclass(frozen=True)
class Rendered:
    """One report after rendering in Chromium.

    Attributes
    ----------
    name : str
        Which report (a key of ``REPORTS``).
    screenshot : Path
        Full-page PNG.
    figures : list of dict
        ``_FIGURE_STATE_JS`` per figure id of the meta tag.
    requests : list of str
        Every URL the page requested.
    errors : list of str
        Console errors and page errors.
    text : str
        The page's visible text.
    height_px : int
        ``document.body.scrollHeight`` [px].
    """

    name: str
    screenshot: Path
    figures: list[dict[str, Any]]
    requests: list[str]
    errors: list[str]
    text: str
    height_px: int


@pytest.fixture(scope="module")
def reports(review_logs: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The reports, written by ``fdi-sim review`` (the CLI, as a user runs it)."""
    out = tmp_path_factory.mktemp("reports")
    paths = {}
    for name, (keys, _) in REPORTS.items():
        paths[name] = out / f"{name}.review.html"
        done = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "review",
                               *(str(review_logs[k]) for k in keys), "--out", str(paths[name])],
                              capture_output=True, text=True, timeout=300, cwd=ROOT)
        assert done.returncode == 0 and paths[name].exists(), (
            f"fdi-sim review {keys} failed (exit {done.returncode}):\n{done.stdout}\n{done.stderr}")
    return paths


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """One headless Debian chromium for the module."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        chromium = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield chromium
        chromium.close()


class _Page:
    """A page on a fresh context, network blocked, requests and errors recorded."""

    def __init__(self, browser: Any) -> None:
        self.requests: list[str] = []
        self.errors: list[str] = []
        self.context = browser.new_context(viewport=VIEWPORT, device_scale_factor=1)
        self.context.route("**/*", self._route)
        self.page = self.context.new_page()
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.on("console", lambda m: self.errors.append(f"console.{m.type}: {m.text}")
                     if m.type == "error" else None)
        self.page.on("pageerror", lambda e: self.errors.append(f"pageerror: {e}"))

    @staticmethod
    def _route(route: Any) -> None:
        if route.request.url.startswith(LOCAL_SCHEMES):
            route.continue_()
        else:
            route.abort()  # recorded by the request handler; the test fails on it

    def open(self, path: Path) -> list[str]:
        """Load ``path``, wait until every figure of the meta tag is drawn; the figure ids."""
        self.page.goto(path.resolve().as_uri(), wait_until="load", timeout=RENDER_TIMEOUT_MS)
        meta = self.page.get_attribute('meta[name="fdi-sim-figures"]', "content")
        assert meta is not None, f"{path.name}: no <meta name=\"fdi-sim-figures\">"
        ids = meta.split()
        assert ids, f"{path.name}: the fdi-sim-figures meta lists no figure"
        from playwright.sync_api import TimeoutError as PlaywrightTimeout

        try:
            self.page.wait_for_function(_ALL_DRAWN_JS, arg=ids, timeout=RENDER_TIMEOUT_MS)
        except PlaywrightTimeout:  # say which figures are not drawn
            state = self.page.evaluate(_FIGURE_STATE_JS, ids)
            bad = [(f["id"], {k: f.get(k) for k in ("missing", "plotly", "svg", "drawn")}) for f in state
                   if f["missing"] or not f["plotly"] or not f["svg"] or not f["drawn"]]
            raise AssertionError(f"{path.name}: figures not rendered within {RENDER_TIMEOUT_MS} ms: {bad}; "
                                 f"errors {self.errors}") from None
        return ids

    def close(self) -> None:
        self.context.close()


def render(browser: Any, name: str, path: Path, shots: Path, css: str = "") -> Rendered:
    """Open the report ``path``, let plotly draw, take a full-page screenshot (after adding
    ``css``, which only the tests of the check itself use)."""
    page = _Page(browser)
    try:
        ids = page.open(path)
        if css:
            page.page.add_style_tag(content=css)
        assert page.page.locator(".fdi-figure").count() == len(ids), f"{name}: .fdi-figure count vs meta"
        figures = page.page.evaluate(_FIGURE_STATE_JS, ids)
        shot = shots / f"{name}.png"
        page.page.screenshot(path=str(shot), full_page=True)
        return Rendered(name, shot, figures, list(page.requests), list(page.errors),
                        page.page.inner_text("body"), int(page.page.evaluate("document.body.scrollHeight")))
    finally:
        page.close()


def _rgb(colour: str) -> np.ndarray:
    """``#rrggbb`` or ``rgb(r, g, b)`` as three ints."""
    if colour.startswith("#") and len(colour) == 7:
        return np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)])
    m = re.fullmatch(r"rgba?\(\s*(\d+)\s*,\s*(\d+)\s*,\s*(\d+)\s*(?:,\s*[\d.]+\s*)?\)", colour)
    assert m is not None, f"unexpected trace colour {colour!r}"
    return np.array([int(g) for g in m.groups()])


def _crop(img: np.ndarray, box: dict[str, float]) -> np.ndarray:
    x0, y0 = max(int(round(box["x"])), 0), max(int(round(box["y"])), 0)
    return img[y0:y0 + int(box["h"]), x0:x0 + int(box["w"])]


def screenshot_problems(r: Rendered) -> list[str]:
    """What is wrong with the screenshot of ``r`` (empty when it is honest)."""
    from PIL import Image

    img = np.asarray(Image.open(r.screenshot).convert("RGB")).astype(np.int16)
    problems: list[str] = []
    empty: list[str] = []
    spread = float(img[::4, ::4].std())  # every 16th pixel: the spread of the page
    if spread < 10:
        problems.append(f"page nearly uniform (pixel std {spread:.1f})")
    n = len(r.figures)
    if not (260 * n <= r.height_px <= 1500 * n + 8000):
        problems.append(f"page height {r.height_px} px implausible for {n} figures")
    if img.shape[0] < 0.95 * r.height_px:
        problems.append(f"screenshot {img.shape[0]} px tall for a {r.height_px} px page")
    for f in r.figures:
        crop = _crop(img, f["box"])
        if crop.size == 0 or f["box"]["h"] < 150:
            problems.append(f"{f['id']}: box {f['box']} too small")
            continue
        if not f["plotly"] or not f["svg"]:
            problems.append(f"{f['id']}: not a rendered plotly plot")
            continue
        ink = float((crop.min(axis=-1) < INK_BELOW).mean())
        if not 0.005 < ink < 0.6:
            problems.append(f"{f['id']}: {ink:.3f} of its box is ink (blank or a solid block)")
        areas = [_crop(img, a) for a in f["areas"] if a["w"] > 20 and a["h"] > 20]
        if not areas:
            problems.append(f"{f['id']}: no subplot area drawn")
            continue
        visible: dict[tuple[str, float], int] = {}
        for colour, opacity, n_points in f["colours"]:
            key = (colour, float(opacity))
            visible[key] = visible.get(key, 0) + int(n_points)
        expected = [k for k, n_points in visible.items() if n_points >= MIN_VISIBLE_POINTS]
        if not expected:
            empty.append(f["id"])  # nothing of it lies inside its axes: the page ships an empty plot
            continue
        px = np.concatenate([a.reshape(-1, 3) for a in areas])
        px = px[(255 - px).max(axis=-1) > NEAR_WHITE]  # white and the #eeeeee grid are no trace
        px = px.astype(np.int32)
        packed, weight = np.unique((px[:, 0] << 16) | (px[:, 1] << 8) | px[:, 2],
                                   return_counts=True)  # distinct colours and their pixel counts
        px = np.stack([packed >> 16, (packed >> 8) & 255, packed & 255], axis=-1)
        found = {}
        for colour, opacity in expected:
            # a translucent line over white, or over another line of the figure (two runs that agree)
            wants = [opacity * _rgb(colour) + (1 - opacity) * under
                     for under in [np.full(3, 255)] + [_rgb(c) for c, _ in expected if c != colour]]
            hit = np.zeros(len(px), dtype=bool)
            for want in wants:
                hit |= np.abs(px - want).max(axis=-1) < COLOUR_TOLERANCE
            found[(colour, opacity)] = int(weight[hit].sum())
        # one run's lines may hide another's where two runs agree (comparison): a third must show
        # a short line needs fewer pixels: 0.3 of its on-screen length (a 2 s trace over a fault band
        # measured 131 px of its exact colour for 205 px of line; over white it is about 1 per px)
        length = {}
        for colour, opacity, px_len in f["lengths"]:
            length[(colour, float(opacity))] = length.get((colour, float(opacity)), 0.0) + px_len
        need_px = max(10.0, min(150.0, 0.3 * max(length.get(k, 0.0) for k in expected)))
        if max(found.values()) < need_px or sum(v >= 20 for v in found.values()) < -(-len(found) // 3):
            problems.append(f"{f['id']}: trace colours in its plot areas (pixels): {found}")
    if empty:  # the report leaves out a figure with nothing to draw and says so (figures._keep_drawable)
        problems.append(f"{len(empty)} of {n} figures have nothing inside their axes: {empty}")
    return problems


@pytest.mark.parametrize("name", list(REPORTS))
def test_report_renders_offline_with_every_figure(browser: Any, reports: dict[str, Path], name: str,
                                                  tmp_path: Path) -> None:
    r = render(browser, name, reports[name], tmp_path)
    where = f"(screenshot {r.screenshot})"
    remote = [u for u in r.requests if not u.startswith(LOCAL_SCHEMES)]
    assert remote == [], f"{name}: the page asked the network for {remote} {where}"
    assert r.requests and r.requests[0].startswith("file:"), r.requests
    assert r.errors == [], f"{name}: console/page errors {r.errors} {where}"
    problems = screenshot_problems(r)
    assert problems == [], f"{name}: the screenshot is not honest: {problems} {where}"
    word = REPORTS[name][1]
    if word is not None:
        assert word in r.text.lower(), f"{name}: the report never says {word!r} {where}"


def test_screenshot_check_fails_on_a_blank_page(browser: Any, tmp_path: Path) -> None:
    """The screenshot check is live: a page whose figures are empty divs fails it."""
    page = tmp_path / "blank.html"
    page.write_text('<html><head><meta name="fdi-sim-figures" content="a b"></head><body>'
                    '<div id="a" class="fdi-figure" style="height:400px"></div>'
                    '<div id="b" class="fdi-figure" style="height:400px"></div></body></html>')
    p = _Page(browser)
    try:
        p.page.goto(page.as_uri())
        figures = p.page.evaluate(_FIGURE_STATE_JS, ["a", "b"])
        shot = tmp_path / "blank.png"
        p.page.screenshot(path=str(shot), full_page=True)
        r = Rendered("blank", shot, figures, p.requests, p.errors, "", 900)
    finally:
        p.close()
    problems = screenshot_problems(r)
    assert any("uniform" in x for x in problems) and any("a: not a rendered plotly" in x for x in problems), problems


def test_a_remote_request_is_seen_and_blocked(browser: Any, tmp_path: Path) -> None:
    """The request recorder and the route are live: a page loading a remote image is caught and
    the image never arrives (the machine's network is not needed: the route aborts it)."""
    page = tmp_path / "remote.html"
    page.write_text('<html><body><img id="i" src="https://example.com/logo.png">'
                    '<script src="https://cdn.plot.ly/plotly-2.35.2.min.js"></script></body></html>')
    p = _Page(browser)
    try:
        p.page.goto(page.as_uri(), wait_until="load")
        loaded = p.page.evaluate("document.getElementById('i').naturalWidth")
        remote = [u for u in p.requests if not u.startswith(LOCAL_SCHEMES)]
    finally:
        p.close()
    assert sorted(remote) == ["https://cdn.plot.ly/plotly-2.35.2.min.js", "https://example.com/logo.png"]
    assert loaded == 0


def test_screenshot_check_fails_when_the_lines_are_not_painted(browser: Any, reports: dict[str, Path],
                                                               tmp_path: Path) -> None:
    """The real fault report with its SVG lines hidden: the DOM still has every trace, the
    screenshot check must see that the pixels lack the trace colours."""
    r = render(browser, "fault-hidden-lines", reports["fault"], tmp_path,
               css="path.js-line, .scatterlayer .trace path { visibility: hidden !important; }")
    problems = screenshot_problems(r)
    lacking = [x for x in problems if "trace colours" in x]
    assert len(lacking) >= len(r.figures) // 2, problems


def test_zoom_on_the_statistic_figure_keeps_points_drawn(browser: Any, reports: dict[str, Path],
                                                         tmp_path: Path) -> None:
    page = _Page(browser)
    try:
        ids = page.open(reports["fault"])
        stat = next(i for i in ids if i.endswith("-statistic"))
        before = page.page.evaluate(_DRAWN_POINTS_JS, stat)
        t0_s, t1_s = page.page.evaluate(f"document.getElementById('{stat}')._fullLayout.xaxis.range")
        a_s, b_s = t0_s + 0.4 * (t1_s - t0_s), t0_s + 0.6 * (t1_s - t0_s)
        page.page.evaluate(f"Plotly.relayout('{stat}', {{'xaxis.range': [{a_s}, {b_s}]}})")
        page.page.wait_for_function(f"""() => {{ const r = document.getElementById('{stat}')._fullLayout.xaxis.range;
            return Math.abs(r[0] - {a_s}) < 1e-6 && Math.abs(r[1] - {b_s}) < 1e-6; }}""", timeout=10_000)
        after = page.page.evaluate(_DRAWN_POINTS_JS, stat)
        shot = tmp_path / "zoomed.png"
        page.page.locator(f"#{stat}").screenshot(path=str(shot))
        # the count is of points in view: a window past the end of the flight holds none
        page.page.evaluate(f"Plotly.relayout('{stat}', {{'xaxis.range': [{t1_s + 100.0}, {t1_s + 200.0}]}})")
        away = page.page.evaluate(_DRAWN_POINTS_JS, stat)
        assert page.errors == [], page.errors
    finally:
        page.close()
    assert before > 0 and after > 0, f"{stat}: points drawn {before} before the zoom, {after} after ({shot})"
    assert away == 0, f"{stat}: {away} points drawn inside a window beyond the flight: the count is not live"
