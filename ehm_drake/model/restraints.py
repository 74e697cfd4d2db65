"""The seat's shear point restraints as the model sees them: where they sit
(`restraint_points`) and, on the implicit design, half of their damper as
SAP compliant distance constraints (`add_restraint_constraints`).

Desai et al. (Sec. II) carry shear by point restraints acting orthogonal to
the contact normal: per tangential axis a linear spring-damper between a
body point and its seat anchor, force-limited (the anchor slides beyond
the limit).  The force law, the limit and the slip are
`ehm_drake.systems.seat.ShearRestraints`.  On the implicit design half of
each restraint's damper is a compliant distance constraint, which SAP
integrates implicitly (`ehm_drake.model.stepping`): from the body point to
an anchor `CONSTRAINT_LENGTH_M` behind it along the axis, so that the
distance changes with the point's motion along that axis only, to first
order.  A distance constraint needs a stiffness; it gets a token one
(`CONSTRAINT_STIFFNESS`).  `ShearRestraints` applies the force law minus
the constraint's force evaluated at the step's start; within the force
limit that leaves the spring at the step's start and the damper half at
its start, half at its end.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.tree import SpatialInertia, UnitInertia

from ..params import CONTACT_PAIRS, ModelParams
from .stepping import step_split

#: Length of the restraint constraints (m): the anchor's distance behind the
#: point.  A sideways motion s changes the distance by s^2 / (2 L) and tilts
#: the constraint's direction by s / L; so does the offset a point settles at
#: from its anchor (taken in the reference posture), and that tilt turns
#: the constraint's damper into a cross-coupling: every lateral anchor lies
#: on the same side, so it breaks the body's left-right symmetry.  At 2 m
#: (a 5 mm offset: 0.25%) vertical excitation moved the trunk in roll
#: 3e-4 of its pitch, which made the fit take noise-only paths for real
#: ones; at 10 km the tilt is below 1e-6 and the coupling below 1e-6 of
#: the real paths (the distance still resolved to 2e-12 m).
CONSTRAINT_LENGTH_M = 1.0e4
#: Stiffness of the restraint constraints (N/m): Drake requires one > 0; the
#: restraint's spring is explicit (`ShearRestraints`), which also cancels
#: this token one exactly, as it does the constraint's whole force at the
#: step's start.
CONSTRAINT_STIFFNESS = 1.0

#: Seat parts, their outward normal in S, and the tangential restraint axes.
SEAT_PARTS = {
    "pan": (np.array([0.0, 0.0, 1.0]), np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])),
    "floor": (np.array([0.0, 0.0, 1.0]), np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])),
    "lower_pad": (np.array([1.0, 0.0, 0.0]), np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])),
    "upper_pad": (np.array([1.0, 0.0, 0.0]), np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])),
}
SEAT_PART_NAMES = tuple(SEAT_PARTS)


def contact_points_B(R_WB, p_BE, semi_axes, normal_W):
    """The point of each contact ellipsoid deepest into its seat part: its
    extreme point against the part's outward normal, in the body frame
    (k x 3; `R_WB` (k, 3, 3) the bodies' orientations, `p_BE`, `semi_axes`
    (k x 3) the ellipsoids, `normal_W` (k x 3) the parts' normals).  With the
    normal m = R_WB^T n in the body frame and D = diag(semi-axes), that point
    is p_BE - D^2 m / |D m|; SAP's point contact acts there (to within the
    penetration), so a contact damper applied by the model's own laws
    belongs there too, not at a body-fixed point that the body's rotation
    carries off it.  In the reference posture (R_WB = I) it is the
    restraint's attachment point p_BP."""
    return deepest_points(np.add.reduce(R_WB * normal_W[:, :, None], axis=1), p_BE, semi_axes)


def deepest_points(m, p_BE, semi_axes):
    """`contact_points_B` from the parts' normals in the body frames, m
    (k x 3): p_BE - D^2 m / |D m|."""
    dm = semi_axes * m
    norm = np.sqrt(np.add.reduce(dm * dm, axis=1))
    return p_BE - (semi_axes * dm) / norm[:, None]


@dataclass(frozen=True)
class RestraintPoint:
    """One shear restraint: a body point, its seat anchor and two axes."""

    name: str  # the body ellipsoid's name
    pair: str  # contact pair (parameter group)
    part: str  # seat part
    body: str  # body name
    p_BP: np.ndarray  # attachment point in the body frame
    p_SA: np.ndarray  # anchor in the seat frame (before slip)
    axes: np.ndarray  # (2, 3) tangential unit vectors in S
    normal: np.ndarray  # (3,) outward normal of the seat part, in S
    #: Seat face position minus the anchor along the normal (m): the
    #: point's penetration is face_offset - (p - p_SA).normal.
    face_offset: float
    #: The contact ellipsoid: its centre in the body frame and its semi-axes
    #: (m; its axes are the body frame's).  Where it touches the seat part
    #: moves over the ellipsoid as the body turns (`contact_points_B`).
    p_BE: np.ndarray
    semi_axes: np.ndarray


def restraint_points(hp) -> list[RestraintPoint]:
    """Restraints at each contact ellipsoid's point nearest its seat part
    (`hp`: the finalized `ehm_drake.model.plant.HumanPlant`).

    The attachment point is the ellipsoid's extreme point against the seat
    part's normal; the anchor is that point in the reference posture.
    """
    inspector = hp.scene_graph.model_inspector()
    plant = hp.plant
    context = plant.CreateDefaultContext()
    points = []
    for pair, (names, part) in CONTACT_PAIRS.items():
        normal, axes = SEAT_PARTS[part]
        for name in names:
            gid, _ = hp.body_geometries[name]
            shape = inspector.GetShape(gid)
            semi = np.array([shape.a(), shape.b(), shape.c()])
            body = plant.GetBodyFromFrameId(inspector.GetFrameId(gid))
            # Ellipsoid axes are parallel to the body frame, which is parallel
            # to S in the reference posture: extreme point along -normal.
            X_BE = inspector.GetPoseInFrame(gid)
            assert np.allclose(X_BE.rotation().matrix(), np.eye(3)), name
            p_BE = X_BE.translation()
            p_BP = p_BE - semi * normal
            X_SB = plant.EvalBodyPoseInWorld(context, body)
            p_SA = X_SB.multiply(p_BP)
            c, size = hp.body.seat.boxes[part]
            face = float(c @ normal + 0.5 * size @ np.abs(normal))
            points.append(RestraintPoint(name, pair, part, body.name(), p_BP, p_SA, axes,
                                         normal, face - float(p_SA @ normal), p_BE, semi))
    return points


def add_restraint_constraints(plant, body, body_geometries: dict, inspector,
                              params: ModelParams) -> tuple:
    """Implicit design, before `Finalize`: one compliant distance constraint
    per restraint point and tangential axis (in the order of
    `restraint_points`, axis by axis), carrying SAP's part of the pair's
    shear damping (`step_split`), anchored on a body welded to
    the world (a distance constraint on the world body itself crashes
    Drake 1.51).  The point's seat anchor is taken in the reference posture
    from `body` (link frames at `Segment.origin_W`, parallel to S); the
    constraint's exact geometry is what `ShearRestraints` reads back.
    Returns the constraint ids."""
    instance = plant.AddModelInstance("restraint_anchors")
    anchor = plant.AddRigidBody("restraint_anchor", instance,
                                SpatialInertia(1.0, np.zeros(3), UnitInertia(1.0, 1.0, 1.0)))
    plant.WeldFrames(plant.world_frame(), anchor.body_frame())
    ids = []
    for pair, (names, part) in CONTACT_PAIRS.items():
        normal, axes = SEAT_PARTS[part]
        r = getattr(params.restraints, pair)
        c_sap = float(step_split(params, r.damping, CONSTRAINT_STIFFNESS)[0])
        for name in names:
            gid, _ = body_geometries[name]
            shape = inspector.GetShape(gid)
            semi = np.array([shape.a(), shape.b(), shape.c()])
            rigid_body = plant.GetBodyFromFrameId(inspector.GetFrameId(gid))
            p_BP = inspector.GetPoseInFrame(gid).translation() - semi * normal
            p_SA = body.segments[rigid_body.name()].origin_W + p_BP
            for axis in axes:
                ids.append(plant.AddDistanceConstraint(
                    rigid_body, p_BP, anchor, p_SA - CONSTRAINT_LENGTH_M * axis,
                    CONSTRAINT_LENGTH_M, CONSTRAINT_STIFFNESS, c_sap))
    return tuple(ids)


@dataclass(frozen=True)
class RestraintConstraints:
    """The restraint constraints as the plant holds them, per restraint axis
    (2 per point, in `restraint_points` order): the anchor point in S (m),
    the free length (m), the stiffness (N/m) and the damping SAP applies at
    the step's end, its own plus the h k of its implicit spring (N s/m)."""

    p_SQ: np.ndarray  # (2n, 3)
    length: np.ndarray  # (2n,)
    stiffness: np.ndarray
    step_damping: np.ndarray

    @classmethod
    def of(cls, plant, ids, time_step: float) -> RestraintConstraints:
        all_specs = plant.GetDefaultDistanceConstraintParams()
        specs = [all_specs[i] for i in ids]
        # The anchor body is welded to the world at X_WB = I: p_BQ is p_SQ.
        assert all(s.bodyB() != plant.world_body().index() for s in specs)
        k = np.array([s.stiffness() for s in specs])
        return cls(p_SQ=np.array([s.p_BQ() for s in specs]),
                   length=np.array([s.distance() for s in specs]), stiffness=k,
                   step_damping=np.array([s.damping() for s in specs]) + time_step * k)
