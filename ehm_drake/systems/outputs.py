"""Measurement-side LeafSystems: body channels, seat forces, blow-up guard.

Body channels are what a motion-capture lab reports: for pelvis, trunk (T8),
head and knees, translation (m) and rotation (rad; roll, pitch, yaw about
the seat's x, y, z) relative to the settled pose, on axes aligned with the
seat.  Translations are absolute: the body's motion relative to the seat
plus the seat's own displacement, so a body moving rigidly with the seat has
transmissibility 1.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import ContactResults
from pydrake.multibody.tree import JointIndex
from pydrake.systems.framework import (
    BasicVector_,
    EventStatus,
    LeafSystem,
    LeafSystem_,
    ValueProducer,
)

from . import PlantScratch, define_system
from .rotations import rotation_from_rpy, rpy_from_rotation, rpy_from_rotation_list
from .seat import SEAT_PART_NAMES

SEGMENTS = ("pelvis", "trunk", "head", "knee_l", "knee_r")
DOFS = ("x", "y", "z", "roll", "pitch", "yaw")
CHANNEL_NAMES = tuple(f"{s}_{d}" for s in SEGMENTS for d in DOFS)
#: The paper's validation channels per excitation direction (Desai et al.
#: III-A): (segment, dof).
PAPER_CHANNELS = {"x": [("pelvis", "x"), ("trunk", "x"), ("head", "x"), ("pelvis", "pitch"),
                        ("trunk", "pitch"), ("head", "pitch")],
                  "y": [("pelvis", "y"), ("trunk", "y"), ("head", "y"), ("trunk", "roll"),
                        ("head", "roll"), ("trunk", "yaw"), ("head", "yaw")],
                  "z": [("pelvis", "z"), ("trunk", "z"), ("head", "z"), ("trunk", "pitch"),
                        ("head", "pitch")]}


@define_system("BodyChannels_", __name__)
def BodyChannels_(T):
    class Impl(LeafSystem_[T]):
        """Inputs ``state`` (plant [q; v]) and ``seat_displacement``;
        output ``channels`` (30 = 5 segments x [x, y, z, roll, pitch, yaw];
        m and rad).  Numeric parameter ``settled_pose``: per segment the
        settled marker position (3) and orientation roll-pitch-yaw (3) in S.
        """

        def _construct(self, plant, markers, settled_pose=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            # markers: list of (body name, p_BM) in SEGMENTS order.
            self._markers = [(b, np.asarray(p, float)) for b, p in markers]
            n = len(self._markers)
            settled = (np.zeros(6 * n) if settled_pose is None
                       else np.asarray(settled_pose, float))
            self._args = (plant, self._markers, settled)
            self._scratch = PlantScratch(plant, T)
            sp = self._scratch.plant
            self._bodies = [sp.GetBodyByName(b) for b, _ in self._markers]
            self._p_BM = np.array([p for _, p in self._markers])[:, :, None]
            self._state = self.DeclareVectorInputPort(
                "state", sp.num_positions() + sp.num_velocities())
            self._disp = self.DeclareVectorInputPort("seat_displacement", 3)
            self._settled = self.DeclareNumericParameter(BasicVector_[T](settled))
            # The settled pose's positions and rotations (transposed), once
            # per parameter value rather than every step.
            self._reference = self.DeclareCacheEntry(
                "settled pose",
                ValueProducer(allocate=lambda: AbstractValue.Make((None, None)),
                              calc=self._calc_reference),
                prerequisites_of_calc={self.all_parameters_ticket()})
            self.DeclareVectorOutputPort("channels", 6 * n, self._calc)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._args, converter=converter)

        @property
        def settled_pose_parameter_index(self):
            return self._settled

        def marker_poses(self, x):
            """[(p_SM, R_SM)] of the markers for plant state x."""
            ctx = self._scratch.set_state(x)
            out = []
            for body, (_, p_BM) in zip(self._bodies, self._markers, strict=True):
                X = self._scratch.plant.EvalBodyPoseInWorld(ctx, body).GetAsMatrix34()
                out.append((X[:, 3] + X[:, :3] @ p_BM, X[:, :3]))
            return out

        def settled_pose_vector(self, x) -> np.ndarray:
            """The ``settled_pose`` parameter value for plant state x."""
            return np.concatenate([np.concatenate([p, rpy_from_rotation(R)])
                                   for p, R in self.marker_poses(x)])

        def _calc_reference(self, context, value):
            ref = context.get_numeric_parameter(self._settled).CopyToVector().reshape(-1, 6)
            # R_ref^T per marker, stacked for the float path with each
            # matrix laid out as the transposed view it is on the other.
            R_ref = np.array([rotation_from_rpy(r) for r in ref[:, 3:]])
            value.set_value((ref[:, :3], R_ref.transpose(0, 2, 1)))

        def _calc(self, context, output):
            x = self._state.Eval(context)
            d = self._disp.Eval(context)
            p_ref, R_ref_T = self._reference.Eval(context)
            if T is not float:
                y = []
                for i, (p, R) in enumerate(self.marker_poses(x)):
                    rel = rpy_from_rotation(R @ R_ref_T[i])
                    y.append(np.concatenate([p - p_ref[i] + d, rel]))
                output.SetFromVector(np.concatenate(y))
                return
            output.SetFromVector(self._channels(x, d, p_ref, R_ref_T))

        def _channels(self, x, d, p_ref, R_ref_T) -> np.ndarray:
            """The channels (float) at plant state x, seat displacement d.
            All markers at once.  Drake's poses are column-major: stacked
            as transposes, each rotation below is laid out as the
            per-marker matrix of `marker_poses`, so the products round the
            same (the channels are bit-for-bit those of the per-marker
            computation; tests/test_force_laws.py)."""
            ctx = self._scratch.set_state(x)
            plant = self._scratch.plant
            X_T = np.array([plant.EvalBodyPoseInWorld(ctx, body).GetAsMatrix34().T
                            for body in self._bodies])
            R = X_T[:, :3, :].transpose(0, 2, 1)
            y = np.empty((len(self._bodies), 6))
            y[:, :3] = X_T[:, 3, :] + (R @ self._p_BM)[:, :, 0] - p_ref + d
            y[:, 3:] = [rpy_from_rotation_list(r) for r in (R @ R_ref_T).tolist()]
            return y.reshape(-1)

        def channels_of_log(self, context, states, displacements) -> np.ndarray:
            """The ``channels`` output (size x samples) at each logged
            sample: plant states (nq + nv x samples) and seat displacements
            (3 x samples), the settled pose from `context` (this system's).
            The same computation as the output port's, sample by sample,
            so the same bits: `vibrate` derives the channels from the
            logged state after the run instead of evaluating them at every
            step (in a run, where the contact solve evicts the caches
            between steps, they cost ~65 us a step at 5 ms, ~10% of it)."""
            p_ref, R_ref_T = self._reference.Eval(context)
            out = np.empty((6 * len(self._bodies), states.shape[1]))
            for k, (x, d) in enumerate(zip(states.T, displacements.T, strict=True)):
                out[:, k] = self._channels(x, d, p_ref, R_ref_T)
            return out

    return Impl


BodyChannels = BodyChannels_[None]


class SeatForces(LeafSystem):
    """Force each seat part exerts on the body, in S (N): contact normal
    force plus the shear restraint force.

    Inputs ``contact_results`` (the plant's) and ``restraint_forces`` (from
    ShearRestraints); output ``seat_forces`` = [pan, floor, lower_pad,
    upper_pad] x [x, y, z].
    """

    def __init__(self, plant, seat_geometries: dict, candidates: int = 0):
        super().__init__()
        self._part_of_geometry = {gid: SEAT_PART_NAMES.index(name)
                                  for name, gid in seat_geometries.items()}
        # The same keyed by the ids' integer values: hashing a GeometryId
        # calls into C++, its value is a Python int (cheaper per contact).
        self._part_of_id_value = {gid.get_value(): part
                                  for gid, part in self._part_of_geometry.items()}
        # With all `candidates` geometry pairs (the scene's unfiltered pairs)
        # in contact, the point contacts come in one order: Drake sorts them
        # by geometry ids.  Their parts, read once from the ids, then serve
        # every such step: a third of the calls per contact.
        self._candidates, self._full_order = candidates, None
        self._contacts = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults()))
        self._restraints = self.DeclareVectorInputPort("restraint_forces", 3 * len(SEAT_PART_NAMES))
        self.DeclareVectorOutputPort("seat_forces", 3 * len(SEAT_PART_NAMES), self._calc)

    def _calc(self, context, output):
        # Summed in Python floats in the order of NumPy's row updates (the
        # same bits; a row update costs ~1 us more per contact).
        out = self._restraints.Eval(context).reshape(-1, 3).tolist()
        results = self._contacts.Eval(context)
        n = results.num_point_pair_contacts()
        order = self._full_order if n == self._candidates else None
        if order is None:
            order = self._parts_in_order(results, n)
            if n == self._candidates:
                self._full_order = order
        for i, (part, sign) in enumerate(order):
            if part is not None:  # the body gets -f_B (f_B: on body B, at the contact point)
                fx, fy, fz = results.point_pair_contact_info(i).contact_force().tolist()
                o = out[part]
                o[0] -= sign * fx
                o[1] -= sign * fy
                o[2] -= sign * fz
        out = np.array(out)
        for i in range(results.num_hydroelastic_contacts()):
            info = results.hydroelastic_contact_info(i)
            surface = info.contact_surface()
            F = info.F_Ac_W().translational()  # on the body of geometry M
            if surface.id_M() in self._part_of_geometry:
                out[self._part_of_geometry[surface.id_M()]] -= F
            elif surface.id_N() in self._part_of_geometry:
                out[self._part_of_geometry[surface.id_N()]] += F
        output.SetFromVector(out.reshape(-1))

    def _parts_in_order(self, results, n):
        """(seat part or None, +1 if the seat is geometry B else -1) of each
        of the `n` point contacts of `results`, from their geometry ids."""
        part_of, order = self._part_of_id_value.get, []
        for i in range(n):
            pair = results.point_pair_contact_info(i).point_pair()
            # The seat parts are geometries of one body, which Drake never
            # pairs with each other: at most one of A, B is a seat part.
            part = part_of(pair.id_B.get_value())
            order.append((part, 1.0) if part is not None
                         else (part_of(pair.id_A.get_value()), -1.0))
        return order


class SimulationDiverged(RuntimeError):
    """The simulation blew up: `time`, `body` and `reason` say when, where, why."""

    def __init__(self, time: float, body: str, reason: str):
        self.time, self.body, self.reason = time, body, reason
        super().__init__(f"simulation diverged at t = {time:.3f} s in body '{body}': {reason}")


class DivergenceGuard(LeafSystem):
    """Checks the plant state at a fixed rate and raises SimulationDiverged
    on NaN/inf, a body falling through the seat, a joint leaving its
    physiological range, or kinetic energy far beyond vibration levels."""

    #: Thresholds (reasons).  The plant moves in the seat's frame (the
    #: excitation is an inertial load), so its kinetic energy is that of the
    #: motion relative to the seat: below 1 J at 1 m/s^2 (0.1 J at most in
    #: 20 s at 0.5 m/s^2 fore-and-aft); 50 J is a 75 kg body at 1.2 m/s.
    #: That motion grows with the seat's acceleration and its energy with
    #: the square, faster once the body slides and the feet lift: at 8 m/s^2
    #: fore-and-aft it peaked at 124 J, at 10 m/s^2 vertical at 243 J (a
    #: foot), bounded over 20 s.  So the limit is MAX_KINETIC_ENERGY_J up to
    #: LEVEL_REF_MS2 and grows with the square of the excitation's level
    #: beyond it (`energy_limit`); an instability grows by a factor per step
    #: and passes any such limit within a few checks.  Joint angles past
    #: 60 deg from the reference posture are outside seated postures.
    MAX_KINETIC_ENERGY_J = 50.0
    LEVEL_REF_MS2 = 1.0
    #: Links lighter than this are the massless links of joint chains (the
    #: Cardan gimbals, the spine's slider): a divergence is reported at the
    #: segment they carry.
    MIN_SEGMENT_MASS_KG = 1e-2
    MAX_JOINT_ANGLE_RAD = math.radians(60.0)
    MIN_PELVIS_HEIGHT_M = -0.05
    #: Check period (s): 20 Hz, a whole number of every allowed step (each
    #: divides the 5 ms output period).  An instability grows by a factor
    #: per step, so from the < 1 J of vibration it passes the 50 J threshold
    #: within a few checks; one so fast that Drake's solver fails before a
    #: check is reported from the last completed state
    #: (`check_after_failure`); a posture lost (joint range, pelvis through
    #: the pan) is reported within 50 ms.  Checking every 10 ms cost ~3% of a
    #: 5 ms step's time in a run (570-580 -> 555-564 us per step).
    PERIOD_S = 0.05

    def __init__(self, hp, period: float = PERIOD_S, level_ms2: float = 0.0):
        """`level_ms2`: the excitation's level (`SeatSignal.level`; 0 for a
        body at rest), which raises the kinetic-energy limit beyond 1 m/s^2
        (`energy_limit`)."""
        super().__init__()
        self._hp = hp
        self.max_kinetic_energy_j = self.energy_limit(level_ms2)
        self._level = float(level_ms2)
        # The plant's kinematics at the state are usually computed already
        # for the force and measurement systems (`PlantScratch`).
        self._scratch = PlantScratch(hp.plant, float)
        plant = hp.plant
        self._state = self.DeclareVectorInputPort(
            "state", plant.num_positions() + plant.num_velocities())
        self.DeclarePeriodicPublishEvent(period, 0.0, self._check)
        self._q_owner = {}
        self._v_owner = {}
        joints = [plant.get_joint(JointIndex(j)) for j in range(plant.num_joints())]
        #: The bodies each body carries (by index), to walk a joint chain.
        self._children = {}
        for joint in joints:
            self._children.setdefault(joint.parent_body().index(), []).append(joint.child_body())
        for joint in joints:
            segment = self._segment_of(joint.child_body()).name()
            for k in range(joint.num_positions()):
                self._q_owner[joint.position_start() + k] = segment
            for k in range(joint.num_velocities()):
                self._v_owner[joint.velocity_start() + k] = segment
        pelvis_joint = plant.GetJointByName("pelvis_free")
        self._pelvis_z = pelvis_joint.position_start() + 5
        self._layout = hp.layout
        self._reference = np.zeros(hp.layout.num_rotational)

    def set_reference(self, q_rot):
        self._reference = np.asarray(q_rot, float).copy()

    @classmethod
    def energy_limit(cls, level_ms2: float) -> float:
        """The kinetic-energy limit (J) for an excitation of `level_ms2`
        (m/s^2): `MAX_KINETIC_ENERGY_J` up to `LEVEL_REF_MS2`, growing
        with the level's square beyond it."""
        if not math.isfinite(level_ms2) or level_ms2 < 0:
            raise ValueError(f"excitation level must be finite and >= 0 m/s^2, got {level_ms2}")
        return cls.MAX_KINETIC_ENERGY_J * max(1.0, (level_ms2 / cls.LEVEL_REF_MS2) ** 2)

    def _segment_of(self, body):
        """`body`, or for a massless link of a joint chain the segment at the
        chain's end (the first body below it with a mass)."""
        while body.default_mass() < self.MIN_SEGMENT_MASS_KG:
            below = self._children.get(body.index(), [])
            if len(below) != 1:
                break
            body = below[0]
        return body

    def _fastest_body(self, ctx) -> str:
        """The segment moving fastest (linear speed + 0.1 m x angular
        speed): where a numerical instability shows first."""
        plant = self._hp.plant
        worst, worst_speed = "?", -1.0
        for bi in plant.GetBodyIndices(self._hp.human):
            body = plant.get_body(bi)
            if body.default_mass() < self.MIN_SEGMENT_MASS_KG:
                continue  # (a chain's link moves with the segment it carries)
            V = plant.EvalBodySpatialVelocityInWorld(ctx, body)
            speed = float(np.linalg.norm(V.translational()) + 0.1 * np.linalg.norm(V.rotational()))
            if speed > worst_speed:
                worst, worst_speed = body.name(), speed
        return worst

    def check_after_failure(self, root_context, error: Exception) -> None:
        """A time step failed inside Drake (`error`, e.g. SAP's solve on a
        state gone to 1e100 between two checks): when the last completed
        state already shows a divergence, raise `SimulationDiverged`
        naming when, where and why, with Drake's message; otherwise return
        (the caller re-raises `error`: not a blow-up this guard sees)."""
        try:
            self._check(self.GetMyContextFromRoot(root_context))
        except SimulationDiverged as e:
            raise SimulationDiverged(e.time, e.body, f"{e.reason}; the next time step failed "
                                     f"in Drake: {error}") from error

    def _check(self, context):
        x = self._state.Eval(context)
        t = context.get_time()
        plant = self._hp.plant
        if not np.isfinite(x).all():
            nq = plant.num_positions()
            i = int(np.flatnonzero(~np.isfinite(x))[0])
            owner = self._q_owner.get(i) if i < nq else self._v_owner.get(i - nq)
            raise SimulationDiverged(t, owner or "?", "state became NaN/inf")
        ctx = self._scratch.set_state(x)
        ke = plant.CalcKineticEnergy(ctx)
        if ke > self.max_kinetic_energy_j:
            level = f"a {self._level:.2g} m/s^2 excitation" if self._level else "the body at rest"
            raise SimulationDiverged(
                t, self._fastest_body(ctx), f"kinetic energy {ke:.3g} J relative to the seat, "
                f"beyond the {self.max_kinetic_energy_j:.3g} J limit for {level} (energy "
                "growing without bound; check gains against the time step)")
        if x[self._pelvis_z] < self.MIN_PELVIS_HEIGHT_M:
            raise SimulationDiverged(
                t, "pelvis", f"fell through the seat pan (height {x[self._pelvis_z]:.3f} m)")
        L = self._layout
        dev = np.abs(x[L.rot_q] - self._reference)
        if dev.max() > self.MAX_JOINT_ANGLE_RAD:
            i = int(np.argmax(dev))
            raise SimulationDiverged(
                t, self._q_owner[int(L.rot_q[i])],
                f"joint {L.names[i]} moved {math.degrees(dev[i]):.0f} deg from its reference "
                "(posture lost)")
        return EventStatus.Succeeded()
