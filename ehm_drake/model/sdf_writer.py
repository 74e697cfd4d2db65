"""Write a `Body` (see anthropometry.py) as SDFormat: the human and its seat.

The SDF files in `sdf/` are this module's output for the 50th-percentile
male (`python -m ehm_drake.model.sdf_writer` regenerates them; a test checks
they are current).  Scaled bodies are written to strings and parsed from
memory.  The SDF holds geometry, kinematics and inertia only; stiffness,
damping, gains and contact properties come from the parameter file.
"""

from __future__ import annotations

import functools
import logging
import math
import sys
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING
from xml.sax.saxutils import escape

import numpy as np

from ..params import CARDAN_JOINTS
from .anthropometry import REFERENCE, Body, build_body
from .restraints import SEAT_PARTS

if TYPE_CHECKING:
    from pydrake.multibody.parsing import Parser

HUMAN_MODEL_NAME = "ehm_human"
SEAT_MODEL_NAME = "ehm_seat"
SDF_DIR = Path(__file__).resolve().parents[2] / "sdf"
HUMAN_SDF_NAME = "ehm_human_50th_male.sdf"
#: The same body with its spherical and universal joints as chains of revolute
#: joints on the Cardan angles (see `human_sdf`).
HUMAN_CARDAN_SDF_NAME = "ehm_human_50th_male_cardan.sdf"
#: Axes of the Cardan chain of each joint type, parent to child (0 = x).
#: Drake's ball joint is R = Rz(yaw) Ry(pitch) Rx(roll) (space-fixed x-y-z):
#: the chain rotates about z first, then y, then x, so its three angles are
#: exactly the ball joint's roll, pitch and yaw.  The universal joint is
#: R = Rx(q1) Ry(q2).
CARDAN_AXES = {"ball": (2, 1, 0), "ball+prismatic": (2, 1, 0), "universal": (0, 1)}
#: Mass (kg) and inertia (kg m^2) of the links between a chain's revolute
#: joints: Drake needs a body there; a tenth of a gram is 1e-5 of the
#: lightest segment (the foot) and changes no mode measurably.
GIMBAL_MASS_KG = 1e-4
GIMBAL_INERTIA = 1e-8
SEAT_SDF_NAME = "ehm_seat_erect_high_support.sdf"
#: The package name under which ``package://`` URLs find the files in ``sdf/``.
PACKAGE_NAME = "ehm_drake"

SKIN = "0.87 0.72 0.60 1"
SEAT_COLOR = "0.25 0.28 0.33 1"
PAD_COLOR = "0.15 0.45 0.70 1"


def model_directory() -> Path:
    """The folder holding package.xml and the SDF files (`sdf/` in the repo).

    Installed, it is the package `ehm_drake.sdf`; when the source tree's
    `ehm_drake` shadows the installed one (running from the checkout), it is
    the checkout's `sdf/` folder.
    """
    try:
        # `ehm_drake.sdf` has no __init__.py: files() gives a MultiplexedPath, whose
        # str() is not a path; a file in it is.
        folder = Path(str(resources.files("ehm_drake.sdf").joinpath("package.xml"))).parent
        if (folder / "package.xml").is_file():
            return folder
    except ModuleNotFoundError:
        pass
    return SDF_DIR


def configure_parser(parser: Parser) -> Parser:
    """Make `package://ehm_drake/...` resolvable for `parser` (for loading
    the packaged files by URL; `packaged_sdf` is the faster way)."""
    pm = parser.package_map()
    if not pm.Contains(PACKAGE_NAME):
        pm.Add(PACKAGE_NAME, str(model_directory()))
    return parser


@functools.cache
def packaged_sdf(name: str) -> str:
    """The text of a packaged SDF file, read once per process.  Drake 1.51
    parses a model from its text in under 1 ms (the seat) to about 10 ms
    (the human), from its file or `package://` URL in 40-55 ms each time
    whatever its size: about a quarter of a fit's model evaluation when
    parsed from the files.  The files refer to no other file."""
    return (model_directory() / name).read_text()


def _f(x: float) -> str:
    """Format a number compactly but exactly enough (1e-9)."""
    s = f"{x:.9f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _vec(v) -> str:
    return " ".join(_f(float(x)) for x in v)


def _pose(p, rpy=(0.0, 0.0, 0.0)) -> str:
    return f"{_vec(p)} {_vec(rpy)}"


def _visual_shapes(name: str, body: Body):
    """Visual-only shapes per segment: (kind, centre_W, dims, rpy)."""
    seg = body.segments[name]
    lm = body.landmarks
    shapes = []
    for e in seg.collision:
        shapes.append(("ellipsoid", e.center_W, e.semi_axes, (0, 0, 0)))

    def capsule(a, b, radius):
        a, b = np.asarray(a, float), np.asarray(b, float)
        d = b - a
        length = float(np.linalg.norm(d))
        pitch = math.atan2(d[0], d[2])
        roll = -math.asin(max(-1.0, min(1.0, d[1] / length)))
        return ("capsule", (a + b) / 2, (radius, length), (roll, pitch, 0.0))

    S = seg.com_W
    if name == "lower_torso":
        shapes.append(("ellipsoid", S, (0.11, 0.155, 0.035), (0, 0, 0)))
    elif name == "middle_torso":
        shapes.append(("ellipsoid", S, (0.115, 0.155, 0.085), (0, 0, 0)))
    elif name == "upper_torso":
        c = 0.5 * (lm["T12L1"] + lm["C7T1"]) + np.array([0.035, 0, 0])
        shapes.append(("ellipsoid", c, (0.105, 0.175, 0.165), (0, 0, 0)))
        if "arm_l" not in body.segments:  # arms lumped into the upper torso
            for side in ("l", "r"):
                shapes += _arm_shapes(lm, side, capsule)
    elif name.startswith("arm_"):
        shapes += _arm_shapes(lm, name[-1], capsule)
    elif name == "viscera":
        shapes.append(("ellipsoid", S, (0.07, 0.07, 0.07), (0, 0, 0)))
    elif name == "neck":
        shapes.append(capsule(lm["C7T1"], lm["C0C1"], 0.045))
    elif name == "head":
        shapes.append(("ellipsoid", S + np.array([0.0, 0, 0.01]), (0.100, 0.078, 0.112), (0, 0, 0)))
    elif name.startswith("lower_leg"):
        side = name[-1]
        shapes.append(capsule(lm[f"knee_{side}"], lm[f"ankle_{side}"], 0.045))
    return shapes


def _arm_shapes(lm, side, capsule):
    return [capsule(lm[f"shoulder_{side}"], lm[f"elbow_{side}"], 0.045),
            capsule(lm[f"elbow_{side}"], lm[f"wrist_{side}"], 0.037),
            capsule(lm[f"wrist_{side}"], lm[f"hand_{side}"], 0.028)]


def gimbal_link(joint_name: str, k: int) -> str:
    """Name of link `k` (1, 2) between the revolute joints of a Cardan chain."""
    return f"{joint_name}_gimbal_{k}"


def cardan_joint(joint_name: str, axis: int) -> str:
    """Name of the revolute joint about `axis` (0, 1, 2) of a Cardan chain."""
    return f"{joint_name}_{'xyz'[axis]}"


def human_sdf(body: Body, cardan_joints=()) -> str:
    """SDFormat text of the human model for `body`.

    The spherical and universal joints named in `cardan_joints` are written
    as chains of revolute joints whose angles are the joint's Cardan angles
    (`CARDAN_AXES`; the paper's "restraint cardan", Desai et al. Sec. II):
    the same kinematics, with the angle rates as generalized velocities, so
    that joint stiffness and PD control act on single-DoF joints, which
    Drake's SAP solver integrates implicitly.  Joint `<name>`'s revolute
    about x is `<name>_x` (`cardan_joint`); the links between them are
    `<name>_gimbal_1`, `_2` (`gimbal_link`).  Revolute joints stay as
    they are."""
    cardan_joints = frozenset(cardan_joints)
    m = body.measures
    lines = [
        '<?xml version="1.0"?>',
        "<!--",
        "  ehm_drake seated human body model (generated by ehm_drake.model.sdf_writer;",
        "  do not edit by hand).",
        f"  Body: mass {_f(m.mass_kg)} kg, stature {_f(m.stature_m)} m, sitting height "
        f"{_f(m.resolved_sitting_height())} m.",
        "  Inertia: de Leva (1996) J Biomech 29:1223, male; see anthropometry.py.",
        "  Axes: x forward (fore-aft), y left (lateral), z up.  Origin of the model",
        "  frame: on the seat-pan surface, mid-sagittal, in the plane of the backrest",
        "  pads' front faces.  Every link frame sits at its proximal joint centre and",
        "  is parallel to the model frame in the reference (initial) posture, so all",
        "  joint angles are zero there.  The pelvis is free (6 DoF); its floating",
        "  joint (roll-pitch-yaw) is added by ehm_drake.model.plant.",
        "-->",
        '<sdf version="1.9">',
        f'<model name="{HUMAN_MODEL_NAME}">',
    ]
    for name, seg in body.segments.items():
        o = seg.origin_W
        I = seg.inertia_W
        lines += [
            f'  <link name="{name}">',
            f"    <!-- {escape(seg.source)} -->",
            f"    <pose>{_pose(o)}</pose>",
            "    <inertial>",
            f"      <pose>{_pose(seg.com_W - o)}</pose>",
            f"      <mass>{_f(seg.mass)}</mass>",
            "      <inertia>",
            f"        <ixx>{_f(I[0, 0])}</ixx><iyy>{_f(I[1, 1])}</iyy><izz>{_f(I[2, 2])}</izz>",
            f"        <ixy>{_f(I[0, 1])}</ixy><ixz>{_f(I[0, 2])}</ixz><iyz>{_f(I[1, 2])}</iyz>",
            "      </inertia>",
            "    </inertial>",
        ]
        for e in seg.collision:
            lines += [
                f'    <collision name="{e.name}">',
                f"      <pose>{_pose(e.center_W - o)}</pose>",
                f"      <geometry><ellipsoid><radii>{_vec(e.semi_axes)}</radii>"
                "</ellipsoid></geometry>",
                "    </collision>",
            ]
        for i, (kind, c, dims, rpy) in enumerate(_visual_shapes(name, body)):
            if kind == "ellipsoid":
                geo = f"<ellipsoid><radii>{_vec(dims)}</radii></ellipsoid>"
            else:
                geo = (f"<capsule><radius>{_f(dims[0])}</radius>"
                       f"<length>{_f(dims[1])}</length></capsule>")
            lines += [
                f'    <visual name="{name}_visual_{i}">',
                f"      <pose>{_pose(np.asarray(c) - o, rpy)}</pose>",
                f"      <geometry>{geo}</geometry>",
                f"      <material><diffuse>{SKIN}</diffuse></material>",
                "    </visual>",
            ]
        lines.append("  </link>")
        if seg.joint == "ball+prismatic":
            lines += [
                '  <link name="spine_slider">',
                "    <!-- Massless in effect: carries the spinal compression DoF between",
                "         the prismatic and the spherical joint (Drake needs a body here). -->",
                f"    <pose>{_pose(o)}</pose>",
                "    <inertial><mass>0.0001</mass><inertia><ixx>1e-08</ixx><iyy>1e-08</iyy>"
                "<izz>1e-08</izz><ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial>",
                "  </link>",
            ]
        if seg.joint_name in cardan_joints and seg.joint in CARDAN_AXES:
            for k in range(1, len(CARDAN_AXES[seg.joint])):
                lines += [
                    f'  <link name="{gimbal_link(seg.joint_name, k)}">',
                    f"    <pose>{_pose(o)}</pose>",
                    f"    <inertial><mass>{GIMBAL_MASS_KG:g}</mass><inertia>"
                    f"<ixx>{GIMBAL_INERTIA:g}</ixx><iyy>{GIMBAL_INERTIA:g}</iyy>"
                    f"<izz>{GIMBAL_INERTIA:g}</izz><ixy>0</ixy><ixz>0</ixz><iyz>0</iyz>"
                    "</inertia></inertial>",
                    "  </link>",
                ]

    for name, seg in body.segments.items():
        if seg.joint in (None, "free"):
            continue
        if seg.joint_name in cardan_joints and seg.joint in CARDAN_AXES:
            parent = seg.parent
            if seg.joint == "ball+prismatic":
                lines += [
                    '  <joint name="spinal_compression" type="prismatic">',
                    f"    <parent>{seg.parent}</parent><child>spine_slider</child>",
                    "    <axis><xyz>0 0 1</xyz><limit><effort>0</effort></limit></axis>",
                    "  </joint>",
                ]
                parent = "spine_slider"
            axes = CARDAN_AXES[seg.joint]
            for k, axis in enumerate(axes):
                child = name if k == len(axes) - 1 else gimbal_link(seg.joint_name, k + 1)
                unit = " ".join("1" if i == axis else "0" for i in range(3))
                lines += [
                    f'  <joint name="{cardan_joint(seg.joint_name, axis)}" type="revolute">',
                    f"    <parent>{parent}</parent><child>{child}</child>",
                    f"    <axis><xyz>{unit}</xyz><limit><effort>0</effort></limit></axis>",
                    "  </joint>",
                ]
                parent = child
        elif seg.joint == "ball":
            lines += [
                f'  <joint name="{seg.joint_name}" type="ball">',
                f"    <parent>{seg.parent}</parent><child>{name}</child>",
                "  </joint>",
            ]
        elif seg.joint == "universal":
            lines += [
                f'  <joint name="{seg.joint_name}" type="universal">',
                f"    <parent>{seg.parent}</parent><child>{name}</child>",
                "    <axis><xyz>1 0 0</xyz><limit><effort>0</effort></limit></axis>",
                "    <axis2><xyz>0 1 0</xyz><limit><effort>0</effort></limit></axis2>",
                "  </joint>",
            ]
        elif seg.joint == "prismatic_z":
            lines += [
                f'  <joint name="{seg.joint_name}" type="prismatic">',
                f"    <parent>{seg.parent}</parent><child>{name}</child>",
                "    <axis><xyz>0 0 1</xyz><limit><effort>0</effort></limit></axis>",
                "  </joint>",
            ]
        elif seg.joint == "revolute":
            lines += [
                f'  <joint name="{seg.joint_name}" type="revolute">',
                f"    <parent>{seg.parent}</parent><child>{name}</child>",
                "    <axis><xyz>0 1 0</xyz><limit><effort>0</effort></limit></axis>",
                "  </joint>",
            ]
        elif seg.joint == "ball+prismatic":
            lines += [
                '  <joint name="spinal_compression" type="prismatic">',
                f"    <parent>{seg.parent}</parent><child>spine_slider</child>",
                "    <axis><xyz>0 0 1</xyz><limit><effort>0</effort></limit></axis>",
                "  </joint>",
                f'  <joint name="{seg.joint_name}" type="ball">',
                f"    <parent>spine_slider</parent><child>{name}</child>",
                "  </joint>",
            ]
        else:  # pragma: no cover - guarded by anthropometry
            raise ValueError(seg.joint)

    lines.append("  <!-- Output marker frames (motion-capture points). -->")
    for marker, (seg_name, p) in body.markers.items():
        o = body.segments[seg_name].origin_W
        lines += [
            f'  <frame name="{marker}_marker" attached_to="{seg_name}">',
            f'    <pose relative_to="{seg_name}">{_pose(p - o)}</pose>',
            "  </frame>",
        ]
    lines += [
        "  <!-- No contact between body segments. -->",
        '  <drake:collision_filter_group name="body_self">',
    ]
    lines += [f"    <drake:member>{n}</drake:member>" for n in body.segments]
    lines += [
        "    <drake:ignored_collision_filter_group>body_self"
        "</drake:ignored_collision_filter_group>",
        "  </drake:collision_filter_group>",
        "</model>",
        "</sdf>",
        "",
    ]
    return "\n".join(lines)


class _NoDeformableHalfSpaceNote(logging.Filter):
    """Drops Drake's note that rigid half-spaces take no part in deformable
    contact, logged when a context of a scene with half-spaces is made: the
    seat's contact surfaces are half-spaces (`seat_sdf`) and the
    model has no deformable body.  Every other Drake message passes."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith(
            "Rigid (non-deformable) half spaces are not currently supported for deformable")


logging.getLogger("drake").addFilter(_NoDeformableHalfSpaceNote())


def seat_sdf(body: Body, cushion_mass_kg: float = 0.0) -> str:
    """SDFormat text of the seat (pan, two backrest pads, floor) for `body`.

    With `cushion_mass_kg` > 0 the pan is its own link ("cushion", that mass)
    on a vertical prismatic joint to the seat frame (the
    `seat_cushion_dynamics` effect; its spring and damper are added in
    code)."""
    lines = [
        '<?xml version="1.0"?>',
        "<!--",
        "  ehm_drake seat: erect posture, high support (Desai et al., Sec. II).",
        "  Generated by ehm_drake.model.sdf_writer; do not edit by hand.",
        "  Axes and origin as the human model: x forward, y left, z up; origin on the",
        "  pan surface, mid-sagittal, in the plane of the pads' front faces.  The pads",
        "  are adjusted to the occupant: lower pad centred at the posterior superior",
        "  iliac spine, upper pad at the inferior angle of the scapula; the floor is",
        "  at the occupant's soles.  The seat is welded to the world; seat motion is",
        "  applied as the equivalent inertial load (ehm_drake.systems.seat).",
        "-->",
        '<sdf version="1.9">',
        f'<model name="{SEAT_MODEL_NAME}">',
        '  <link name="seat">',
    ]
    cushion = []
    for name, (c, size) in body.seat.boxes.items():
        color = PAD_COLOR if "pad" in name else SEAT_COLOR
        target = cushion if (name == "pan" and cushion_mass_kg > 0) else lines
        # The contact surface is the box's face towards the body as a
        # half-space (SDFormat plane; its size is the face's, for the
        # reader: Drake's half-space is unbounded).  The body's contact
        # ellipsoids touch the faces well inside their edges in every
        # posture, where the two are the same surface; the half-space's
        # penetration is closed-form, the box's FCL's GJK/EPA: with the
        # excitation in C++, a step 2-3% fewer instructions (docs/history/speed.md).
        normal = SEAT_PARTS[name][0]
        face = np.asarray(c, float) + 0.5 * (np.asarray(size, float) @ normal) * normal
        target += [
            f'    <collision name="{name}">',
            f"      <pose>{_pose(face)}</pose>",
            f"      <geometry><plane><normal>{_vec(normal)}</normal>"
            f"<size>{_vec(np.asarray(size, float)[normal == 0])}</size></plane></geometry>",
            "    </collision>",
            f'    <visual name="{name}_visual">',
            f"      <pose>{_pose(c)}</pose>",
            f"      <geometry><box><size>{_vec(size)}</size></box></geometry>",
            f"      <material><diffuse>{color}</diffuse></material>",
            "    </visual>",
        ]
    # Backrest frame carrying the pads (visual only), 0.06 m behind them.
    top = body.seat.boxes["upper_pad"][0][2] + 0.15
    lines += [
        '    <visual name="backrest_frame_visual">',
        f"      <pose>{_pose((-0.075, 0.0, top / 2))}</pose>",
        f"      <geometry><box><size>{_vec((0.03, 0.42, top))}</size></box></geometry>",
        f"      <material><diffuse>{SEAT_COLOR}</diffuse></material>",
        "    </visual>",
        "  </link>",
        '  <joint name="seat_weld" type="fixed">',
        "    <parent>world</parent><child>seat</child>",
        "  </joint>",
    ]
    if cushion_mass_kg > 0:
        m = cushion_mass_kg
        Ixx = m * (0.5**2 + 0.05**2) / 12
        lines += [
            '  <link name="cushion">',
            "    <!-- Seat cushion as its own mass (seat_cushion_dynamics effect). -->",
            "    <inertial><pose>0.23 0 -0.025 0 0 0</pose>",
            f"      <mass>{_f(m)}</mass><inertia><ixx>{_f(Ixx)}</ixx><iyy>{_f(Ixx)}</iyy>"
            f"<izz>{_f(m * 0.5**2 / 6)}</izz><ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia>",
            "    </inertial>",
            *[line.replace("    <", "    <", 1) for line in cushion],
            "  </link>",
            '  <joint name="cushion_z" type="prismatic">',
            "    <parent>seat</parent><child>cushion</child>",
            "    <axis><xyz>0 0 1</xyz><limit><effort>0</effort></limit></axis>",
            "  </joint>",
        ]
    lines += ["</model>", "</sdf>", ""]
    return "\n".join(lines)


def write_reference_sdf(directory: Path = SDF_DIR) -> list[Path]:
    """Regenerate the 50th-percentile SDF files in `directory`."""
    body = build_body(REFERENCE)
    paths = []
    for fname, text in ((HUMAN_SDF_NAME, human_sdf(body)),
                        (HUMAN_CARDAN_SDF_NAME, human_sdf(body, CARDAN_JOINTS)),
                        (SEAT_SDF_NAME, seat_sdf(body))):
        path = Path(directory) / fname
        path.write_text(text)
        paths.append(path)
    return paths


if __name__ == "__main__":  # pragma: no cover
    for p in write_reference_sdf(Path(sys.argv[1]) if len(sys.argv) > 1 else SDF_DIR):
        print("wrote", p)
