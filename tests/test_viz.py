"""3D visualization: the HTML recordings are self-contained and hold the animation
(decoded), bad input is named, and a headless Chromium renders the recording."""

from __future__ import annotations

import argparse
import base64
import io
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from ehm_drake.model.anthropometry import REFERENCE, BodyMeasures
from ehm_drake.params import params_from_dict
from ehm_drake.viz import (
    VizError,
    add_viz_arguments,
    build_viewer,
    handle_viz,
    live_view,
    mode_animation_html,
    positions_from_result,
    record_html,
)

CHROMIUM = Path("/usr/bin/chromium")
needs_chromium = pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason="/usr/bin/chromium is not installed (apt-get install -y chromium); CI installs it")

# Headless Chromium with software WebGL (SwiftShader), no network or background
# services; --virtual-time-budget lets the page's timers (the animation) advance
# that many virtual ms before the screenshot.  Without
# --run-all-compositor-stages-before-draw, Chromium 156 under load never returned
# on 6 of 12 renders of a recording (stop 56, beside a blind run; killed after
# 45 s, the others took 3-9 s); with it, 14 of 14 returned in 3-18 s.
CHROMIUM_FLAGS = (
    "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
    "--run-all-compositor-stages-before-draw",
    "--disable-quic", "--no-first-run", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--window-size=800,600",
)

#: Module fixtures: the module's tests stay on one xdist worker (built once).
pytestmark = pytest.mark.xdist_group("viz")
#: Console messages of SwiftShader itself (performance notes), not of the page.
BENIGN_CONSOLE = ("GL Driver Message",)


@pytest.fixture(scope="module")
def viewer_params():
    return params_from_dict({})


@pytest.fixture(scope="module")
def motion(viewer_params):
    """2 s of synthetic motion at 200 Hz: the pelvis bobs 2 cm at 1 Hz, the
    trunk pitches 0.1 rad at 0.5 Hz (no simulation needed)."""
    v = build_viewer(viewer_params)
    q0 = v.plant.GetPositions(v.plant_context)
    t = np.arange(401) / 200.0
    q = np.tile(q0, (t.size, 1))
    q[:, 5] += 0.02 * np.sin(2 * np.pi * t)
    q[:, 14] += 0.1 * np.sin(np.pi * t)
    return t, q


def _commands(html: str) -> list[dict]:
    """The Meshcat commands embedded in a StaticHtml page (msgpack in data URLs)."""
    msgpack = pytest.importorskip("msgpack")
    blobs = re.findall(r'fetch\("data:application/octet-binary;base64,([A-Za-z0-9+/=]+)"\)',
                       html)
    return [msgpack.unpackb(base64.b64decode(b)) for b in blobs]


def _animation(html: str) -> dict:
    anims = [c for c in _commands(html) if c.get("type") == "set_animation"]
    assert len(anims) == 1
    return anims[0]


def _track(anim: dict, body: str, prop: str) -> list:
    for a in anim["animations"]:
        if a["path"].endswith(f"/{body}"):
            for tr in a["clip"]["tracks"]:
                if tr["name"] == f".{prop}":
                    return tr["keys"]
    raise AssertionError(f"no {prop} track for {body}")


def test_record_html_is_self_contained_and_holds_the_animation(tmp_path, viewer_params,
                                                                motion):
    t, q = motion
    path = record_html(viewer_params, REFERENCE, t, q, tmp_path / "run.html", fps=30)
    html = path.read_text()
    # Self-contained: viewer code inline, nothing loaded from the network.
    assert "MeshCat.Viewer" in html and len(html) > 1_000_000
    assert not re.search(r"<script[^>]*\bsrc\s*=", html, re.I)
    assert not re.search(r"<link[^>]*\bhref\s*=\s*[\"']?(https?:)?//", html, re.I)
    assert not re.search(r"@import\s+url\(\s*[\"']?https?:", html, re.I)
    anim = _animation(html)
    assert anim["options"]["play"]
    paths = {a["path"].rsplit("/", 1)[-1] for a in anim["animations"]}
    assert {"pelvis", "upper_torso", "head", "thigh_l", "foot_r"} <= paths
    assert all(a["clip"]["fps"] == pytest.approx(30.0) for a in anim["animations"])
    # 2 s at 30 frames/s: 61 frames, one key per frame.
    pelvis = _track(anim, "pelvis", "position")
    assert len(pelvis) == 61
    assert [k["time"] for k in pelvis[:3]] == [0, 1, 2]
    z = np.array([k["value"][2] for k in pelvis])
    # The pelvis bobs +-2 cm at 1 Hz: frame 7.5 (0.25 s) is the top.
    assert np.ptp(z) == pytest.approx(0.04, abs=2e-3)
    assert z[15] - z[0] == pytest.approx(0.0, abs=1e-9)  # t = 0.5 s: back to the start
    # The first frame is the plant's own pelvis pose at q(0).
    v = build_viewer(viewer_params)
    v.plant.SetPositions(v.plant_context, q[0])
    X = v.plant.EvalBodyPoseInWorld(v.plant_context, v.plant.GetBodyByName("pelvis"))
    np.testing.assert_allclose(pelvis[0]["value"], X.translation(), atol=1e-12)
    # The trunk moves, the feet (leg joints at rest) only follow the pelvis.
    head = np.array([k["value"] for k in _track(anim, "head", "position")])
    assert np.ptp(head[:, 0]) > 0.02


def test_playback_speed_sets_the_number_of_frames(tmp_path, viewer_params, motion):
    t, q = motion
    html = record_html(viewer_params, REFERENCE, t, q, tmp_path / "slow.html", speed=0.5,
                       fps=20).read_text()
    anim = _animation(html)
    assert len(_track(anim, "pelvis", "position")) == 81  # 2 s at half speed, 20 frames/s


def test_mode_animation_two_cycles(tmp_path, viewer_params):
    v = build_viewer(viewer_params)
    q0 = v.plant.GetPositions(v.plant_context)
    shape = np.zeros(31, complex)
    shape[5] = 1j  # pelvis z, 90 deg out of phase
    path = mode_animation_html(viewer_params, REFERENCE, q0, shape, 4.2, tmp_path / "m.html",
                               amplitude=0.01, cycle_time_s=1.0, fps=30)
    anim = _animation(path.read_text())
    assert anim["options"]["repetitions"] > 1  # looped
    z = np.array([k["value"][2] for k in _track(anim, "pelvis", "position")])
    assert len(z) == 60  # two cycles of 1 s at 30 frames/s
    # Re(j e^{j phi}) = -sin(phi): two cycles of a 1 cm sine, starting at rest.
    phi = 2 * np.pi * 2 * np.arange(60) / 60
    np.testing.assert_allclose(z - z[0], -0.01 * np.sin(phi), atol=1e-9)


def test_bad_input_is_named(tmp_path, viewer_params, motion):
    t, q = motion
    with pytest.raises(VizError, match="30 columns.*31"):
        record_html(viewer_params, REFERENCE, t, q[:, :30], tmp_path / "a.html")
    with pytest.raises(VizError, match="shape"):
        record_html(viewer_params, REFERENCE, t[:-1], q, tmp_path / "a.html")
    bad = t.copy()
    bad[5] = bad[4]
    with pytest.raises(VizError, match=r"times must increase strictly \(times\[5\]"):
        record_html(viewer_params, REFERENCE, bad, q, tmp_path / "a.html")
    qn = q.copy()
    qn[3, 7] = np.nan
    with pytest.raises(VizError, match="sample 3, column 7"):
        record_html(viewer_params, REFERENCE, t, qn, tmp_path / "a.html")
    with pytest.raises(VizError, match="speed"):
        record_html(viewer_params, REFERENCE, t, q, tmp_path / "a.html", speed=0)
    with pytest.raises(VizError, match="does not exist"):
        record_html(viewer_params, REFERENCE, t, q, tmp_path / "nope" / "a.html")
    with pytest.raises(VizError, match="params must be a ModelParams"):
        record_html({}, REFERENCE, t, q, tmp_path / "a.html")
    with pytest.raises(VizError, match="shape_q"):
        mode_animation_html(viewer_params, REFERENCE, None, np.ones(30), 2.0,
                            tmp_path / "m.html")
    with pytest.raises(VizError, match="freq_hz"):
        mode_animation_html(viewer_params, REFERENCE, None, np.ones(31), -1.0,
                            tmp_path / "m.html")
    with pytest.raises(VizError, match="no plant positions"):
        positions_from_result(argparse.Namespace(times=t))


def test_replay_of_a_simulation(tmp_path):
    from ehm_drake.simulation import simulate

    params = params_from_dict({"simulation": {"settle_time_s": 0.3, "onset_time_s": 0.5}})
    body = BodyMeasures(mass_kg=60.0, stature_m=1.62)
    _, result = simulate(params, body, duration=1.5, rms=1.0, direction="x")
    q = positions_from_result(result)
    assert q.shape == (result.times.size, 31)
    assert np.ptp(q[:, 3]) > 1e-4  # the pelvis moves fore-aft
    path = record_html(params, body, result.times, q, tmp_path / "sim.html")
    pelvis = _track(_animation(path.read_text()), "pelvis", "position")
    assert len(pelvis) == int(np.floor((result.times[-1] - result.times[0]) * 30 + 1e-9)) + 1


def test_handle_viz_and_live_view(tmp_path, viewer_params, motion, monkeypatch):
    t, q = motion
    parser = argparse.ArgumentParser()
    add_viz_arguments(parser)
    assert handle_viz(parser.parse_args([]), viewer_params, REFERENCE, (t, q)) is None
    out = tmp_path / "cli.html"
    args = parser.parse_args(["--record", str(out), "--meshcat", "--viz-speed", "2"])
    monkeypatch.setattr("sys.stdin", io.StringIO(""))  # not a terminal: no wait
    meshcat = handle_viz(args, viewer_params, REFERENCE, (t, q))
    assert meshcat.web_url().startswith("http://")
    # 2 s at double speed, 30 frames/s: 31 frames, in the file and in the live viewer.
    assert len(_track(_animation(out.read_text()), "pelvis", "position")) == 31
    assert len(_track(_animation(meshcat.StaticHtml()), "pelvis", "position")) == 31
    # A second replay into the same viewer replaces the first.
    same = live_view(viewer_params, REFERENCE, t[:201], q[:201], meshcat=meshcat)
    assert same is meshcat
    assert len(_track(_animation(meshcat.StaticHtml()), "pelvis", "position")) == 31


# ---------------------------------------------------------------------------
# Headless Chromium
# ---------------------------------------------------------------------------


def _run_once(cmd: list[str], timeout_s: float):
    """One Chromium run in its own process group, the whole group killed on a hang
    (Chromium's renderer and GPU children hold the pipes open after the parent dies)."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout_s)
        return subprocess.CompletedProcess(cmd, proc.returncode, out, err)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return None


def _chromium(tmp_path: Path, html: Path, *extra: str, budget_ms: int = 4000,
              attempts: int = 3, timeout_s: float = 150.0):
    """Headless Chromium on ``html``; a hung render is killed and retried.

    Headless Chromium with a virtual-time budget could hang (CI failed on it at stops 54
    and 55: 900 s, no output); `CHROMIUM_FLAGS` removes the cause found, this stays as the
    safety net.  A render takes 3-18 s under load, so 150 s is a hang, not a slow machine.
    """
    for _ in range(attempts):
        profile = tmp_path / f"profile-{len(list(tmp_path.glob('profile-*')))}"
        cmd = [str(CHROMIUM), *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
               f"--virtual-time-budget={budget_ms}", *extra, html.resolve().as_uri()]
        proc = _run_once(cmd, timeout_s)
        if proc is not None:
            return proc
    pytest.fail(f"headless Chromium hung {attempts} times ({timeout_s:.0f} s each) on {html.name}")


def _screenshot(tmp_path: Path, html: Path, name: str, budget_ms: int = 4000):
    png = tmp_path / f"{name}.png"
    proc = _chromium(tmp_path, html, f"--screenshot={png}", "--enable-logging=stderr", "--v=0",
                     budget_ms=budget_ms)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert png.is_file(), proc.stderr[-2000:]
    return mpimg.imread(png)[..., :3], proc.stderr


def _coloured_fraction(img: np.ndarray) -> float:
    """Share of pixels that are not grey: Meshcat's background and grid are grey,
    the body (skin tone) and the seat (blue) are not."""
    return float(np.mean(img.max(axis=-1) - img.min(axis=-1) > 0.1))


def _console(log: str) -> list[str]:
    return [line for line in log.splitlines() if ":CONSOLE" in line
            and not any(b in line for b in BENIGN_CONSOLE)]


@needs_chromium
def test_chromium_renders_the_recording(tmp_path, viewer_params, motion):
    from pydrake.geometry import Meshcat

    t, q = motion
    html = record_html(viewer_params, REFERENCE, t, q, tmp_path / "run.html")
    img, log = _screenshot(tmp_path, html, "run")
    assert img.shape == (600, 800, 3)
    assert _console(log) == []  # no JavaScript error or warning of the page
    assert "Uncaught" not in log
    # The model is drawn: ~15 % of the window is coloured (body and seat).
    assert _coloured_fraction(img) > 0.02
    # Control: the same viewer without the model is grey (~0.1 %).
    blank = tmp_path / "blank.html"
    blank.write_text(Meshcat().StaticHtml())
    empty, _ = _screenshot(tmp_path, blank, "blank")
    assert _coloured_fraction(empty) < 0.005
    # The DOM after the scripts ran: the viewer's pane holds a WebGL canvas.
    proc = _chromium(tmp_path, html, "--dump-dom")
    assert proc.returncode == 0
    assert 'id="meshcat-pane"' in proc.stdout
    assert re.search(r'<div id="meshcat-pane"[^>]*>\s*<canvas', proc.stdout)


@needs_chromium
def test_chromium_plays_the_animation(tmp_path, viewer_params):
    # The trunk leans steadily from 0.6 rad back to 0.6 rad forward over 10 s.
    # The animation's start in Chromium's virtual time varies by ~2 s on a
    # loaded machine, so the motion is monotonic (no two times share a pose)
    # rather than periodic.  A still scene renders identically at any time.
    v = build_viewer(viewer_params)
    q0 = v.plant.GetPositions(v.plant_context)
    t = np.linspace(0.0, 10.0, 101)
    q = np.tile(q0, (t.size, 1))
    q[:, [7, 10, 14]] += np.linspace(-0.2, 0.2, t.size)[:, None]
    html = record_html(viewer_params, REFERENCE, t, q, tmp_path / "lean.html", fps=10)
    early, _ = _screenshot(tmp_path, html, "early", budget_ms=1000)
    late, _ = _screenshot(tmp_path, html, "late", budget_ms=6000)
    assert _coloured_fraction(early) > 0.02 and _coloured_fraction(late) > 0.02
    changed = float(np.mean(np.abs(early - late).max(axis=-1) > 0.1))
    assert changed > 0.01  # ~0.6 rad of trunk lean apart: measured 2.0 %


def test_a_hung_render_is_killed_with_its_children(tmp_path):
    # The stand-in for a hung Chromium: a shell whose child holds the pipes open.
    pid_file = tmp_path / "child.pid"
    proc = _run_once(["sh", "-c", f"sleep 60 & echo $! > {pid_file}; wait"], timeout_s=1.0)
    assert proc is None
    child = int(pid_file.read_text())
    with pytest.raises(ProcessLookupError):
        for _ in range(50):  # reaped by init within moments of the kill
            os.kill(child, 0)
            time.sleep(0.1)
        raise AssertionError("the hung child survived")
    done = _run_once(["sh", "-c", "echo ok"], timeout_s=30.0)
    assert done.returncode == 0 and done.stdout == "ok\n"
