"""The HTML report of ``identify --report`` rendered by headless Chromium: the screenshot shows every
embedded plot, 1:1, non-blank, where the page puts it; the page needs nothing from outside.

Chromium is Debian's ``chromium`` package (``apt-get install -y chromium``); the rendering test skips
when it is not installed.
"""
import itertools
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

from .pngcheck import IMG_RE, decode_png, embedded_images, find_image, ink_stats, saturated_share

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
WINDOW = (1280, 4000)
#: every figure is 11 in x 100 dpi wide
FIG_WIDTH_PX = 1100
#: identification torques, validation torques (6 joints: 3 rows of 1.25 in axes, 0.6 in gaps, 0.6 in
#: top and 0.85 in bottom margins = 6.4 in), singular values (2.4 + 0.35 + 0.55 = 3.3 in)
EXPECTED_HEIGHTS_PX = [640, 640, 330]
#: the torque curves' colours (measured, reconstructed) and the singular values' one
MEASURED, RECONSTRUCTED, SINGULAR = (0x1F, 0x77, 0xB4), (0xD6, 0x27, 0x28), (0x15, 0x65, 0xC0)


def _count_colour(rgb, colour, tol=10):
    return int(np.sum(np.all(np.abs(rgb.astype(int) - np.array(colour)) <= tol, axis=2)))


def test_html_is_self_contained(rx90_html_report):
    path, _ = rx90_html_report
    html = path.read_text(encoding="utf-8")
    # every src/href is an embedded PNG
    refs = re.findall(r'(?i)\b(?:src|href|srcset|poster|data)\s*=\s*"([^"]*)"', html)
    assert refs and all(r.startswith("data:image/png;base64,") for r in refs)
    text = IMG_RE.sub("<img>", html)
    for pattern in (r"(?i)\b(?:https?|ftp|wss?):", r"(?i)(?:src|href)\s*=\s*['\"]?//", r"(?i)<script", r"(?i)<link\b",
                    r"(?i)<iframe", r"(?i)@import", r"(?i)url\s*\(", r"(?i)<object", r"(?i)<embed"):
        assert not re.search(pattern, text), f"external reference in the report: {pattern}"
    # no temporary file left beside it (written through a temporary sibling and a rename)
    assert sorted(p.name for p in path.parent.iterdir()) == ["report.html", "report.json"]


def test_embedded_images_are_non_blank_plots_of_the_expected_size(rx90_html_report):
    path, _ = rx90_html_report
    imgs = embedded_images(path.read_text(encoding="utf-8"))
    assert len(imgs) == len(EXPECTED_HEIGHTS_PX)
    for k, ((png, w, h), eh) in enumerate(zip(imgs, EXPECTED_HEIGHTS_PX)):
        rgb = decode_png(png)
        assert rgb.shape == (h, w, 3) == (eh, FIG_WIDTH_PX, 3), f"image {k}"
        ink, colours = ink_stats(rgb)
        assert ink > 0.03 and colours > 200, f"image {k} looks blank: ink {ink:.3f}, {colours} colours"
        assert saturated_share(rgb) > 0.003, f"image {k} has no coloured curve"
        if k < 2:  # torque plots: measured and reconstructed curves both drawn
            assert _count_colour(rgb, MEASURED) > 150 and _count_colour(rgb, RECONSTRUCTED) > 150, f"image {k}"
        else:
            assert _count_colour(rgb, SINGULAR) > 300


def _screenshot(html_path, tmp_path):
    png = tmp_path / "screenshot.png"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars",
           f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={png}",
           f"--window-size={WINDOW[0]},{WINDOW[1]}", html_path.resolve().as_uri()]
    env = dict(os.environ, HOME=str(tmp_path))
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    assert png.is_file(), f"chromium wrote no screenshot (exit {proc.returncode}):\n{proc.stderr[-2000:]}"
    return png


@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium is not installed "
                                             "(Debian package 'chromium': apt-get install -y chromium)")
def test_chromium_screenshot_shows_every_plot(rx90_html_report, tmp_path):
    path, _ = rx90_html_report
    imgs = embedded_images(path.read_text(encoding="utf-8"))
    shot = decode_png(_screenshot(path, tmp_path).read_bytes())
    assert shot.shape == (WINDOW[1], WINDOW[0], 3)
    ink, colours = ink_stats(shot)
    assert ink > 0.05 and colours > 1000, f"page looks blank: ink {ink:.3f}, {colours} colours"
    assert saturated_share(shot) > 0.001
    placed = []
    for k, (png, w, h) in enumerate(imgs):
        img = decode_png(png)
        where = find_image(shot, img)
        assert where is not None, f"image {k} ({w}x{h}) is not shown 1:1 in the screenshot"
        y, x = where
        region = shot[y:y + h, x:x + w]
        r_ink, r_colours = ink_stats(region)
        assert r_ink > 0.03 and r_colours > 200, f"image {k} region is blank in the screenshot"
        placed.append((y, x, h, w))
    # in page order, one below the other, none overlapping, left-aligned in the content column
    ys = [p[0] for p in placed]
    assert ys == sorted(ys)
    assert all(a[0] + a[2] <= b[0] for a, b in itertools.pairwise(placed))
    assert len({p[1] for p in placed}) == 1
    # text and tables above the first plot (title, error norms): ink outside the images too
    top = shot[:placed[0][0]]
    assert ink_stats(top)[0] > 0.02
