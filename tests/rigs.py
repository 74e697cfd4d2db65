"""Small test rigs built with the model's machinery (MultibodyPlant, SAP,
SeatInertialLoad driven by the seat acceleration) with known dynamics."""

from __future__ import annotations

import numpy as np
from pydrake.geometry import AddContactMaterial, HalfSpace, ProximityProperties, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlantConfig
from pydrake.multibody.tree import PrismaticJoint, PrismaticSpring, SpatialInertia, UnitInertia
from pydrake.systems.framework import DiagramBuilder

from ehm_drake.systems.seat import SeatInertialLoad


def contact_props(k, c):
    props = ProximityProperties()
    AddContactMaterial(dissipation=None, point_stiffness=k, friction=CoulombFriction(0, 0),
                       properties=props)
    props.AddProperty("material", "relaxation_time", c / k)
    return props


def chain_rig(masses, k_ground, c_ground, k_springs=(), c_springs=(), h=1e-5):
    """Masses stacked on vertical prismatic joints: the first sits on a
    half-space through sphere contact (k_ground, c_ground, SAP's linear
    Kelvin-Voigt), each next one on the previous through a spring-damper.
    Returns (diagram, plant, root context at the static equilibrium)."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=h, discrete_contact_approximation="sap", contact_model="point",
        use_sampled_output_ports=False), builder)
    inst = plant.AddModelInstance("rig")
    parent = plant.world_frame()
    joints = []
    for i, m in enumerate(masses):
        body = plant.AddRigidBody(f"m{i}", inst, SpatialInertia(m, [0, 0, 0],
                                                                UnitInertia.SolidSphere(0.05)))
        joint = plant.AddJoint(PrismaticJoint(f"z{i}", parent, body.body_frame(), [0, 0, 1]))
        joints.append(joint)
        if i == 0:
            plant.RegisterCollisionGeometry(body, RigidTransform(), Sphere(0.05), "c",
                                            contact_props(k_ground, c_ground))
        else:
            plant.AddForceElement(PrismaticSpring(joint, 0.0, k_springs[i - 1]))
            joint.set_default_damping(c_springs[i - 1])
        parent = body.body_frame()
    ground = ProximityProperties()
    AddContactMaterial(dissipation=None, point_stiffness=1e10, friction=CoulombFriction(0, 0),
                       properties=ground)
    ground.AddProperty("material", "relaxation_time", 0.0)
    plant.RegisterCollisionGeometry(plant.world_body(), RigidTransform(), HalfSpace(), "ground",
                                    ground)
    plant.Finalize()
    load = builder.AddSystem(SeatInertialLoad(plant, inst))
    builder.Connect(plant.get_state_output_port(), load.GetInputPort("state"))
    builder.Connect(load.get_output_port(), plant.get_applied_generalized_force_input_port())
    builder.ExportInput(load.GetInputPort("seat_acceleration"), "seat_acceleration")
    builder.ExportOutput(plant.get_state_output_port(), "state")
    diagram = builder.Build()
    ctx = diagram.CreateDefaultContext()
    diagram.get_input_port().FixValue(ctx, np.zeros(3))
    # Static equilibrium: springs carry the weight above them.
    g = 9.81
    above = np.cumsum(np.asarray(masses)[::-1])[::-1]
    q = [0.05 - above[0] * g / k_ground]
    for i in range(1, len(masses)):
        q.append(-above[i] * g / k_springs[i - 1])
    plant.SetPositions(plant.GetMyMutableContextFromRoot(ctx), q)
    return diagram, plant, ctx


def continuous_modes(masses, k_ground, c_ground, k_springs=(), c_springs=()):
    """Exact continuous-time (wn, zeta) of the chain, absolute coordinates."""
    n = len(masses)
    M = np.diag(masses)
    K = np.zeros((n, n))
    C = np.zeros((n, n))
    K[0, 0] += k_ground
    C[0, 0] += c_ground
    for i in range(1, n):
        for (a, b), sgn in (((i, i), 1), ((i - 1, i - 1), 1), ((i, i - 1), -1), ((i - 1, i), -1)):
            K[a, b] += sgn * k_springs[i - 1]
            C[a, b] += sgn * c_springs[i - 1]
    A = np.block([[np.zeros((n, n)), np.eye(n)],
                  [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    s = np.linalg.eigvals(A)
    s = s[s.imag > 0] if np.all(np.abs(s.imag) > 0) else s
    wn = np.abs(s)
    order = np.argsort(wn)
    return wn[order], (-s.real / np.abs(s))[order]
