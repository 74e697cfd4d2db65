"""Figures: seated posture (paper Fig. 5), time responses, gains.

Matplotlib with the non-interactive Agg backend; every function writes a
PNG and returns its path.  Plots show degrees where the API uses radians.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np  # noqa: E402
from matplotlib.patches import Polygon, Rectangle  # noqa: E402

#: Joint chains drawn as the skeleton (child body names, proximal to distal).
_CHAINS = (
    ("pelvis", "lower_torso", "middle_torso", "upper_torso", "neck", "head"),
    ("pelvis", "thigh_l", "lower_leg_l", "foot_l"),
)


_VIEW_AXES = {"side": (0, 2), "front": (1, 2)}


def _skeleton_points(plant, context, human, view="side"):
    """Projected points of the joint centres along the chains: side view
    (x, z) or front view (y, z; both legs)."""
    chains = []
    extra = (("pelvis", "thigh_r", "lower_leg_r", "foot_r"),) if view == "front" else ()
    for chain in _CHAINS + extra:
        pts = []
        for name in chain:
            body = plant.GetBodyByName(name, human)
            pts.append(plant.EvalBodyPoseInWorld(context, body).translation())
        # Extend to the distal landmark: vertex for the head, toe for the foot.
        last = plant.GetBodyByName(chain[-1], human)
        X = plant.EvalBodyPoseInWorld(context, last)
        tip = np.array([0.02, 0.0, 0.17]) if chain[-1] == "head" else np.array([0.21, 0, -0.045])
        pts.append(X.multiply(tip))
        chains.append(np.array(pts)[:, list(_VIEW_AXES[view])])
    return chains


def _ellipse_outlines(plant, scene_graph, context, human, n=48, view="side"):
    """Projected outlines of the body's collision ellipsoids (side: x-z
    section, front: y-z section)."""
    inspector = scene_graph.model_inspector()
    out = []
    for bi in plant.GetBodyIndices(human):
        body = plant.get_body(bi)
        X_WB = plant.EvalBodyPoseInWorld(context, body)
        for gid in plant.GetCollisionGeometriesForBody(body):
            shape = inspector.GetShape(gid)
            if not hasattr(shape, "a"):
                continue
            X_BG = inspector.GetPoseInFrame(gid)
            t = np.linspace(0, 2 * np.pi, n)
            if view == "side":
                local = np.stack([shape.a() * np.cos(t), np.zeros(n), shape.c() * np.sin(t)], 1)
            else:
                local = np.stack([np.zeros(n), shape.b() * np.cos(t), shape.c() * np.sin(t)], 1)
            world = np.array([X_WB.multiply(X_BG.multiply(p)) for p in local])
            out.append(world[:, list(_VIEW_AXES[view])])
    return out


def plot_posture(model, states: dict, path: str | Path | None,
                 title: str = "Seated posture", view: str = "side", ax=None) -> Path | None:
    """Side (x-z) or front (y-z) view of the body on the seat for each
    labelled plant state.

    `states` maps a label to a plant state vector [q; v] (or q); the first
    is drawn with its contact ellipsoids, the others as skeletons.  With
    `ax`, draws into it and returns None.
    """
    plant = model.plant
    ctx = plant.CreateDefaultContext()
    i0, i1 = _VIEW_AXES[view]
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(6.4, 6.4))
    for name, (c, size) in model.hp.body.seat.boxes.items():
        if view == "front" and "pad" in name:
            continue  # the pads are behind the body
        ax.add_patch(Rectangle((c[i0] - size[i0] / 2, c[i1] - size[i1] / 2), size[i0],
                               size[i1], color="#1f5f99" if "pad" in name else "#555555",
                               alpha=0.8, zorder=1))
    styles = ["-", "--", ":", "-."]
    colors = ["#c0392b", "#2c3e50", "#27ae60", "#8e44ad"]
    for i, (label, x) in enumerate(states.items()):
        x = np.asarray(x)
        plant.SetPositions(ctx, x[: plant.num_positions()])
        if i == 0:
            for outline in _ellipse_outlines(plant, model.hp.scene_graph, ctx, model.hp.human,
                                             view=view):
                ax.add_patch(Polygon(outline, closed=True, facecolor="#e8c4a8", alpha=0.5,
                                     edgecolor="#b08060", zorder=2))
        for j, pts in enumerate(_skeleton_points(plant, ctx, model.hp.human, view)):
            ax.plot(pts[:, 0], pts[:, 1], styles[i % 4], color=colors[i % 4], lw=2, marker="o",
                    ms=3, zorder=3, label=label if j == 0 else None)
    ax.set_aspect("equal")
    ax.set_xlim(*((-0.15, 0.95) if view == "side" else (-0.55, 0.55)))
    ax.set_ylim(model.hp.body.landmarks["floor"][2] - 0.08, 1.0)
    ax.set_xlabel("x fore-aft (m)" if view == "side" else "y lateral (m)")
    ax.set_ylabel("z vertical (m)")
    ax.set_title(title, fontsize=9 if not own else 11)
    ax.legend(loc="upper right", fontsize=7)
    ax.grid(alpha=0.3)
    if not own:
        return None
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_mode_shapes(model, linear_model, modes, path: str | Path, amplitude_m: float = 0.06,
                     columns: int = 4) -> Path:
    """Mode shapes: each mode's extreme deflections (+/- amplitude at the
    largest body point) over the equilibrium, side view for sagittal
    modes, front view for lateral ones."""
    nq = model.plant.num_positions()
    q0 = linear_model.x0[linear_model.state_groups["q"]][:nq]
    rows = int(np.ceil(len(modes) / columns))
    fig, axes = plt.subplots(rows, columns, figsize=(3.2 * columns, 3.4 * rows), squeeze=False)
    for ax, mode in zip(axes.flat, modes, strict=False):
        shape = linear_model.position_shape(mode).real * amplitude_m
        view = "front" if "(lateral)" in mode.label else "side"
        plot_posture(model, {"+": q0 + shape, "-": q0 - shape}, None,
                     f"{mode.freq_hz:.2f} Hz, zeta {mode.damping_ratio:.2f}\n{mode.label}",
                     view, ax)
    for ax in list(axes.flat)[len(modes):]:
        ax.axis("off")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_poles(modes, path: str | Path, f_max: float = 15.0) -> Path:
    """Continuous-equivalent poles (Hz) of the closed loop."""
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for kind, marker, color in (("oscillatory", "x", "#c0392b"), ("real", "o", "#2471a3"),
                                ("integrator", "s", "#27ae60"), ("unstable", "X", "k")):
        s = np.array([m.s for m in modes if m.kind == kind]) / (2 * np.pi)
        if len(s):
            ax.plot(s.real, np.abs(s.imag), marker, color=color, label=kind, ls="none")
    ax.axvline(0, color="k", lw=0.8)
    ax.set_xlim(-f_max, 1)
    ax.set_ylim(0, f_max)
    ax.set_xlabel("Re(s)/2pi (1/s)")
    ax.set_ylabel("|Im(s)|/2pi (Hz)")
    ax.set_title("Poles of the linearized closed loop")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_responses(result, path: str | Path, segments=("pelvis", "trunk", "head"),
                   max_seconds: float = 20.0) -> Path:
    """Seat acceleration and segment motions versus time."""
    t = result.times
    k = t <= t[0] + max_seconds
    fig, axes = plt.subplots(1 + 2 * len(segments), 1, figsize=(8, 2 + 1.6 * 2 * len(segments)),
                             sharex=True)
    axes[0].plot(t[k], result.seat_acceleration[k])
    axes[0].set_ylabel("seat acc.\n(m/s²)")
    axes[0].legend(["x", "y", "z"], fontsize=7, ncol=3, loc="upper right")
    row = 1
    for seg in segments:
        tr = np.column_stack([result.channel(seg, d) for d in "xyz"]) * 1000.0
        rot = np.degrees(np.column_stack([result.channel(seg, d)
                                          for d in ("roll", "pitch", "yaw")]))
        axes[row].plot(t[k], tr[k])
        axes[row].set_ylabel(f"{seg}\nx,y,z (mm)")
        axes[row + 1].plot(t[k], rot[k])
        axes[row + 1].set_ylabel(f"{seg}\nr,p,y (deg)")
        row += 2
    axes[-1].set_xlabel("time (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
