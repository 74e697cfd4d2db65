"""3D visualization of the seated human in Meshcat: replays, HTML recordings, mode shapes.

The simulation diagram (`ehm_drake.diagram.build_diagram`) is finished and has no
visualizer; a run is shown by replaying its plant positions q(t) into a separate,
lightweight *viewer* diagram: the same body and seat (`add_seated_human` with the same
parameters and body measures) with a `MeshcatVisualizer` of the illustration geometry
(the SDF's visual shapes of the segments and the seat).  Nothing is simulated there.

* :func:`record_html` writes a self-contained HTML animation (Meshcat's
  ``StaticHtml``: the viewer's JavaScript and the recorded animation in one file,
  ~2.3 MB plus ~1 kB per frame; it opens offline in any WebGL browser).
* :func:`live_view` plays the motion in a live Meshcat (the animation can be replayed
  and scrubbed with the viewer's controls) and returns the Meshcat handle; the server
  lives as long as the handle.
* :func:`mode_animation_html` animates a mode shape
  ``q0 + amplitude * Re(shape * exp(j 2 pi f t))`` for two cycles (looped).

``positions`` are the plant's generalized positions q (31 per sample, in the plant's
order: the pelvis' roll-pitch-yaw floating joint, then the joints), e.g.
``SimulationResult.positions`` (see :func:`positions_from_result`).  Positions are
resampled linearly to the animation's frame rate.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .model.anthropometry import REFERENCE, BodyMeasures
from .params import ModelParams

#: Camera of the recordings: in front of the subject, to its left, slightly above,
#: looking at the lap (seat frame: x forward, y left, z up; metres).
CAMERA_POSITION = (1.5, 1.25, 0.85)
CAMERA_TARGET = (0.2, 0.0, 0.3)
DEFAULT_FPS = 30.0


class VizError(ValueError):
    """Bad input to a visualization function (names the argument)."""


@dataclass
class Viewer:
    """A viewer diagram: plant + scene graph + MeshcatVisualizer, and its contexts."""

    diagram: Any
    plant: Any
    visualizer: Any
    meshcat: Any
    context: Any
    plant_context: Any
    visualizer_context: Any
    fps: float

    @property
    def num_positions(self) -> int:
        return int(self.plant.num_positions())

    def show(self, q: np.ndarray, t: float = 0.0) -> None:
        """Publish the pose q (recorded as a frame at time t while recording)."""
        self.context.SetTime(float(t))
        self.plant.SetPositions(self.plant_context, np.asarray(q, float))
        self.visualizer.ForcedPublish(self.visualizer_context)


def _check_fps(fps: float) -> float:
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not (
            math.isfinite(fps) and 1.0 <= fps <= 240.0):
        raise VizError(f"fps must be a number in [1, 240] frames/s, got {fps!r}")
    return float(fps)


def _check_speed(speed: float) -> float:
    if isinstance(speed, bool) or not isinstance(speed, (int, float)) or not (
            math.isfinite(speed) and speed > 0):
        raise VizError(f"speed must be a positive finite number (1 = real time), got {speed!r}")
    return float(speed)


def build_viewer(params: ModelParams, measures: BodyMeasures = REFERENCE, meshcat: Any = None,
                 fps: float = DEFAULT_FPS) -> Viewer:
    """The viewer diagram of the body `measures` on its seat, drawing into `meshcat`
    (a new `pydrake.geometry.Meshcat` if None), recording at `fps` frames/s."""
    from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role
    from pydrake.systems.framework import DiagramBuilder

    from .model.plant import add_seated_human

    if not isinstance(params, ModelParams):
        raise VizError(f"params must be a ModelParams (ehm_drake.params.load_params()), got "
                       f"{type(params).__name__}")
    if not isinstance(measures, BodyMeasures):
        raise VizError(f"measures must be a BodyMeasures, got {type(measures).__name__}")
    fps = _check_fps(fps)
    if meshcat is None:
        meshcat = Meshcat()
    builder = DiagramBuilder()
    hp = add_seated_human(builder, params, measures)
    vp = MeshcatVisualizerParams()
    vp.role = Role.kIllustration
    # The recording's frame rate is 1 / publish_period; nothing publishes
    # periodically here (no simulator), frames are forced one by one.
    vp.publish_period = 1.0 / fps
    vis = MeshcatVisualizer.AddToBuilder(builder, hp.scene_graph, meshcat, vp)
    diagram = builder.Build()
    diagram.set_name("ehm_viewer")
    ctx = diagram.CreateDefaultContext()
    return Viewer(diagram, hp.plant, vis, meshcat, ctx, hp.plant.GetMyContextFromRoot(ctx),
                  vis.GetMyContextFromRoot(ctx), fps)


def _check_motion(times: Any, positions: Any, nq: int) -> tuple[np.ndarray, np.ndarray]:
    try:
        t = np.asarray(times, dtype=float)
        q = np.asarray(positions, dtype=float)
    except (TypeError, ValueError):
        raise VizError("times and positions must be numeric arrays") from None
    if t.ndim != 1 or t.size == 0:
        raise VizError(f"times must be a non-empty 1-D array (s), got shape {t.shape}")
    if q.ndim == 1 and t.size == 1:
        q = q[None, :]
    if q.ndim != 2 or q.shape[0] != t.size:
        raise VizError(f"positions must have shape (len(times), {nq}) = ({t.size}, {nq}), got "
                       f"{q.shape}")
    if q.shape[1] != nq:
        raise VizError(f"positions has {q.shape[1]} columns; the plant has {nq} generalized "
                       "positions q (pass plant positions, not the 30 body channels)")
    if not np.all(np.isfinite(t)):
        raise VizError(f"times has a non-finite value at index {int(np.argmin(np.isfinite(t)))}")
    bad = np.argwhere(~np.isfinite(q))
    if bad.size:
        raise VizError(f"positions has a non-finite value at sample {int(bad[0, 0])}, "
                       f"column {int(bad[0, 1])}")
    if t.size > 1 and np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0))
        raise VizError(f"times must increase strictly (times[{k + 1}] = {t[k + 1]} after "
                       f"{t[k]})")
    return t, q


def _resample(t: np.ndarray, q: np.ndarray, frame_times: np.ndarray) -> np.ndarray:
    """Linear interpolation of the rows of q (at times t) at `frame_times`."""
    if t.size == 1:
        return np.repeat(q, frame_times.size, axis=0)
    k = np.clip(np.searchsorted(t, frame_times, side="right") - 1, 0, t.size - 2)
    w = np.clip((frame_times - t[k]) / (t[k + 1] - t[k]), 0.0, 1.0)[:, None]
    return (1.0 - w) * q[k] + w * q[k + 1]


def _record(viewer: Viewer, frames: np.ndarray, repetitions: int = 1) -> None:
    """Record one frame per row of `frames` (at 1/fps intervals) and publish the
    animation to the viewer's Meshcat."""
    from pydrake.geometry import MeshcatAnimation

    vis = viewer.visualizer
    vis.DeleteRecording()
    vis.StartRecording(set_transforms_while_recording=False)
    for k, q in enumerate(frames):
        viewer.show(q, k / viewer.fps)
    vis.StopRecording()
    anim = vis.get_mutable_recording()
    anim.set_loop_mode(MeshcatAnimation.LoopMode.kLoopRepeat)
    anim.set_repetitions(int(repetitions))
    anim.set_clamp_when_finished(True)
    vis.PublishRecording()
    viewer.show(frames[-1], (len(frames) - 1) / viewer.fps)


def _set_camera(meshcat: Any) -> None:
    meshcat.SetCameraPose(np.array(CAMERA_POSITION), np.array(CAMERA_TARGET))


def _motion_frames(times: np.ndarray, q: np.ndarray, speed: float, fps: float) -> np.ndarray:
    span = float(times[-1] - times[0]) / speed
    n = max(1, int(math.floor(span * fps + 1e-9)) + 1)
    return _resample(times, q, times[0] + np.arange(n) / fps * speed)


def _write_html(meshcat: Any, path: str | Path) -> Path:
    path = Path(path)
    if path.parent and not path.parent.exists():
        raise VizError(f"cannot write {path}: folder {path.parent} does not exist")
    if path.exists() and path.is_dir():
        raise VizError(f"cannot write {path}: it is a folder")
    path.write_text(meshcat.StaticHtml(), encoding="utf-8")
    return path


def record_html(params: ModelParams, measures: BodyMeasures, times: Any, positions: Any,
                path: str | Path, speed: float = 1.0, fps: float = DEFAULT_FPS) -> Path:
    """Write a self-contained HTML animation of the motion q(t).

    Parameters
    ----------
    params, measures : the model the positions belong to (geometry of body and seat).
    times : (N,) sample times, s, increasing.
    positions : (N, 31) plant generalized positions q.
    path : the HTML file to write.
    speed : playback speed (1 = real time, 0.5 = slow motion).
    fps : frames per second of the animation.

    Returns
    -------
    Path of the file (it needs no network: viewer code and animation are embedded).
    """
    speed = _check_speed(speed)
    viewer = build_viewer(params, measures, None, fps)
    t, q = _check_motion(times, positions, viewer.num_positions)
    _set_camera(viewer.meshcat)
    _record(viewer, _motion_frames(t, q, speed, viewer.fps))
    return _write_html(viewer.meshcat, path)


def live_view(params: ModelParams, measures: BodyMeasures, times: Any, positions: Any,
              meshcat: Any = None, speed: float = 1.0, fps: float = DEFAULT_FPS) -> Any:
    """Play the motion q(t) in a live Meshcat and return the Meshcat handle.

    `meshcat` defaults to a new ``pydrake.geometry.StartMeshcat()``; its URL is
    ``handle.web_url()``.  A given `meshcat` is cleared first.  The animation plays once
    and can be replayed from the viewer's "Animation" controls.  Keep the handle: the
    server stops with it.
    """
    from pydrake.geometry import StartMeshcat

    speed = _check_speed(speed)
    if meshcat is None:
        meshcat = StartMeshcat()
    meshcat.Delete()
    viewer = build_viewer(params, measures, meshcat, fps)
    t, q = _check_motion(times, positions, viewer.num_positions)
    _set_camera(meshcat)
    _record(viewer, _motion_frames(t, q, speed, viewer.fps))
    return meshcat


def mode_animation_html(params: ModelParams, measures: BodyMeasures, q0: Any, shape_q: Any,
                        freq_hz: float, path: str | Path, amplitude: float = 0.03,
                        cycles: int = 2, cycle_time_s: float = 2.0,
                        fps: float = DEFAULT_FPS) -> Path:
    """Write an HTML animation of a mode shape, ``q0 + amplitude * Re(shape * e^{j 2 pi f t})``,
    over `cycles` cycles (looped in the viewer).

    Parameters
    ----------
    q0 : (31,) positions the mode oscillates about (e.g. the settled pose); None: the
        reference posture.
    shape_q : (31,) complex mode shape in q, e.g. ``LinearModel.position_shape(mode)``
        (scaled so the largest body-channel motion is 1: `amplitude` is then that motion
        in m, rotations counted x 0.3 m).
    freq_hz : the mode's frequency (Hz).
    amplitude : scale of the shape.
    cycles : number of cycles recorded.
    cycle_time_s : displayed duration of one cycle (the motion is slowed down or sped
        up to it; the frequency is not visible otherwise).
    """
    viewer = build_viewer(params, measures, None, fps)
    nq = viewer.num_positions
    if q0 is None:
        q0 = viewer.plant.GetPositions(viewer.plant_context)
    q0 = np.asarray(q0, dtype=float)
    if q0.shape != (nq,) or not np.all(np.isfinite(q0)):
        raise VizError(f"q0 must be {nq} finite plant positions, got shape {q0.shape}")
    shape = np.asarray(shape_q, dtype=complex)
    if shape.shape != (nq,) or not np.all(np.isfinite(shape)):
        raise VizError(f"shape_q must be {nq} finite (complex) values, got shape {shape.shape}")
    for name, v in (("freq_hz", freq_hz), ("amplitude", amplitude),
                    ("cycle_time_s", cycle_time_s)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                math.isfinite(v) and v > 0):
            raise VizError(f"{name} must be a positive finite number, got {v!r}")
    if isinstance(cycles, bool) or not isinstance(cycles, int) or cycles < 1:
        raise VizError(f"cycles must be a positive integer, got {cycles!r}")
    n = int(round(cycles * cycle_time_s * viewer.fps))
    phase = 2.0 * math.pi * cycles * np.arange(n) / n  # 2 pi f t, t over `cycles` periods
    frames = q0 + amplitude * np.real(np.exp(1j * phase)[:, None] * shape[None, :])
    _set_camera(viewer.meshcat)
    _record(viewer, frames, repetitions=10_000)
    return _write_html(viewer.meshcat, path)


def positions_from_result(result: Any) -> np.ndarray:
    """The plant positions q(t), shape (N, 31), of a SimulationResult.

    Raises
    ------
    VizError
        If the result carries no positions (made by a version that did not record them).
    """
    q = getattr(result, "positions", None)
    if q is None:
        raise VizError(
            f"{type(result).__name__} has no plant positions to replay (no 'positions' "
            "field or it is None); simulate with a version of ehm_drake.simulation that "
            "records them, or pass (times, positions) arrays")
    q = np.asarray(q, dtype=float)
    times = np.asarray(getattr(result, "times", []), dtype=float)
    if q.ndim != 2 or q.shape[0] != times.size:
        raise VizError(f"result.positions has shape {q.shape}, expected ({times.size}, nq)")
    return q


# ---------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------


def add_viz_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--meshcat``, ``--record FILE`` and ``--viz-speed X`` to a command."""
    g = parser.add_argument_group("3D view")
    g.add_argument("--meshcat", action="store_true",
                   help="play the run in a live Meshcat viewer (prints its URL; on a "
                   "terminal waits for Enter before exiting)")
    g.add_argument("--record", metavar="FILE",
                   help="write a self-contained HTML animation of the run (opens offline)")
    g.add_argument("--viz-speed", type=float, default=1.0, metavar="X",
                   help="playback speed of --meshcat/--record (1 = real time; default "
                   "%(default)s)")


def handle_viz(args: argparse.Namespace, params: ModelParams, measures: BodyMeasures,
               result_or_times_q: Any) -> Any:
    """After a simulation: record (``--record``) and/or show (``--meshcat``) the run.

    `result_or_times_q` is a SimulationResult (with positions) or a (times, positions)
    pair.  Returns the live Meshcat handle (or None without ``--meshcat``).
    """
    record = getattr(args, "record", None)
    live = getattr(args, "meshcat", False)
    if not record and not live:
        return None
    speed = getattr(args, "viz_speed", 1.0)
    if isinstance(result_or_times_q, tuple) and len(result_or_times_q) == 2:
        times, q = result_or_times_q
    else:
        q = positions_from_result(result_or_times_q)
        times = result_or_times_q.times
    if record:
        path = record_html(params, measures, times, q, record, speed=speed)
        print(f"3D animation -> {path}", file=sys.stderr)
    if not live:
        return None
    meshcat = live_view(params, measures, times, q, speed=speed)
    print(f"Meshcat viewer: {meshcat.web_url()}", file=sys.stderr)
    if sys.stdin is not None and sys.stdin.isatty():
        try:
            input("press Enter to close the viewer ")
        except (EOFError, KeyboardInterrupt):
            pass
    return meshcat


__all__ = [
    "VizError", "Viewer", "add_viz_arguments", "build_viewer", "handle_viz", "live_view",
    "mode_animation_html", "positions_from_result", "record_html",
]
