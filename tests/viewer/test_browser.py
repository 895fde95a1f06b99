"""The viewer in a real browser: Debian's headless Chromium, driven by playwright, loads
the page viser serves and shows the scene, the panel and the toggles."""

from __future__ import annotations

import io
import shutil

import numpy as np
import pytest
from helpers import free_port, partial_views, random_motion

from o3d_rpointhop import register, register_multiway
from o3d_rpointhop.datasets import make_object

pytestmark = pytest.mark.slow

pytest.importorskip("viser")
sync_api = pytest.importorskip("playwright.sync_api")
CHROMIUM = shutil.which("chromium")
if CHROMIUM is None:
    pytest.skip(
        "Debian's chromium is not installed (scripts/setup.sh --test installs it)",
        allow_module_level=True,
    )

# The flags a sandboxed, offline machine needs (no background connections).
FLAGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


@pytest.fixture(scope="module")
def browser():
    with sync_api.sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        yield chromium
        chromium.close()


def _open(browser, server):
    page = browser.new_page(viewport={"width": 1000, "height": 700})
    page.goto(f"http://127.0.0.1:{server.get_port()}", wait_until="domcontentloaded")
    page.wait_for_selector("canvas", timeout=60_000)
    return page


def _share_near(png: bytes, colour, tolerance=40) -> float:
    from PIL import Image

    pixels = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).reshape(-1, 3).astype(int)
    return float((np.abs(pixels - np.array(colour)).max(axis=1) < tolerance).mean())


def test_a_pair_registration_is_drawn_with_its_panel_and_toggles(browser):
    from o3d_rpointhop.viewer import show_registration

    target = make_object(3000, shape_seed=4, sample_seed=1)
    rot, shift = random_motion(1, 0.3)
    source = make_object(3000, shape_seed=4, sample_seed=2) @ rot.T + shift
    result = register(source, target)
    server = show_registration(source, target, result, port=free_port(), block=False)
    try:
        page = _open(browser, server)
        for label in (
            "Registration",
            "fitness",
            "converged: True",
            "aligned source",
            "global step: matches it kept",
            "global step: other matches",
            "inlier correspondences",
        ):
            page.get_by_text(label, exact=False).first.wait_for(timeout=30_000)
        assert len(server.get_clients()) == 1
        page.wait_for_timeout(2000)  # the points arrive after the page
        shot = page.screenshot()
        green = _share_near(shot, (44, 160, 44))
        assert green > 0.002, green  # the aligned source is on screen
        page.get_by_text("aligned source").last.click()  # its toggle (the legend's is first)
        page.wait_for_timeout(1000)
        assert _share_near(page.screenshot(), (44, 160, 44)) < green / 4
    finally:
        server.stop()


def test_a_reconstruction_is_drawn_scan_by_scan(browser):
    from helpers import partial_views

    from o3d_rpointhop.viewer import show_multiway

    scans, _ = partial_views(3, seed=1)
    result = register_multiway(scans, random_state=0)
    server = show_multiway(scans, result, port=free_port(), block=False)
    try:
        page = _open(browser, server)
        for label in (
            "Reconstruction",
            "3 of 3 scans placed",
            "scan 0",
            "scan 2",
            "pose graph edges",
        ):
            page.get_by_text(label, exact=False).first.wait_for(timeout=30_000)
    finally:
        server.stop()


def test_missing_viewer_names_the_install_line(monkeypatch):
    import sys

    from o3d_rpointhop import viewer

    monkeypatch.setitem(sys.modules, "viser", None)
    with pytest.raises(ImportError, match=r"pip install '\.\[view\]'"):
        viewer.show_registration(np.zeros((10, 3)), np.zeros((10, 3)), np.eye(4))


def test_the_view_command_serves_saved_results_and_transforms(tmp_path, monkeypatch, capsys):
    from o3d_rpointhop import viewer
    from o3d_rpointhop.cli import main
    from o3d_rpointhop.poses import write_matrix

    served = []
    monkeypatch.setattr(viewer, "show_registration", lambda s, t, r, **kw: served.append(r))
    monkeypatch.setattr(viewer, "show_multiway", lambda s, r, **kw: served.append(r))
    target = make_object(1500, shape_seed=6, sample_seed=1)
    source = make_object(1500, shape_seed=6, sample_seed=2) + [0.1, 0.0, 0.0]
    np.save(tmp_path / "s.npy", source)
    np.save(tmp_path / "t.npy", target)
    files = [str(tmp_path / "s.npy"), str(tmp_path / "t.npy")]
    assert main(["register", *files, "--result", str(tmp_path / "r.json"), "--view"]) == 0
    assert main(["view", str(tmp_path / "r.json"), *files]) == 0
    np.testing.assert_array_equal(served[0].transformation, served[1].transformation)
    write_matrix(tmp_path / "T.txt", served[0].transformation)
    assert main(["view", str(tmp_path / "T.txt"), *files]) == 0
    assert served[2].converged and served[2].steps[0].name == "evaluate"
    assert main(["view", str(tmp_path / "r.json"), files[0]]) == 1  # a pair needs two
    assert main(["view", str(tmp_path / "missing.json"), *files]) == 1
    (tmp_path / "garbage.json").write_text("{not json")
    assert main(["view", str(tmp_path / "garbage.json"), *files]) == 1
    assert "garbage.json: not a JSON file" in capsys.readouterr().err
    # A saved multiway result is shown with every scan, named by its file.
    from o3d_rpointhop.registration import MultiwayResult

    scans, _ = partial_views(3, seed=1)
    names = []
    for k, scan in enumerate(scans):
        np.save(tmp_path / f"scan{k}.npy", scan)
        names.append(str(tmp_path / f"scan{k}.npy"))
    register_multiway(scans, random_state=0).save(tmp_path / "m.json")
    captured = {}
    monkeypatch.setattr(viewer, "show_multiway", lambda s, r, **kw: captured.update(r=r, s=s, **kw))
    assert main(["view", str(tmp_path / "m.json"), *names, "--port", "8123"]) == 0
    assert isinstance(captured["r"], MultiwayResult) and len(captured["s"]) == 3
    assert captured["names"] == ["scan0.npy", "scan1.npy", "scan2.npy"]
    assert captured["port"] == 8123 and captured["host"] == "127.0.0.1"
    saved = MultiwayResult.load(tmp_path / "m.json")
    for a, b in zip(captured["r"].poses, saved.poses, strict=True):
        np.testing.assert_array_equal(a, b)
