"""The body, the seat and the plant: DoFs, segments, mass, SDF, scaling."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RollPitchYaw
from pydrake.systems.framework import DiagramBuilder

from ehm_drake.model.anthropometry import (
    DE_LEVA_1996_MALE,
    REFERENCE,
    BodyMeasures,
    build_body,
)
from ehm_drake.model.plant import CARDAN_JOINTS, add_seated_human
from ehm_drake.model.sdf_writer import (
    HUMAN_CARDAN_SDF_NAME,
    HUMAN_SDF_NAME,
    SEAT_SDF_NAME,
    human_sdf,
    model_directory,
    seat_sdf,
)
from ehm_drake.systems.joints import cardan_to_generalized, rpy_rate_matrices

#: Module fixtures: the module's tests stay on one xdist worker (built once).
pytestmark = pytest.mark.xdist_group("model")

SEGMENTS = {"pelvis", "lower_torso", "middle_torso", "upper_torso", "neck", "head",
            "thigh_l", "thigh_r", "lower_leg_l", "lower_leg_r", "foot_l", "foot_r"}


@pytest.fixture(scope="module")
def hp(params):
    return add_seated_human(DiagramBuilder(), params)


def test_plant_has_31_dofs_12_segments_and_paper_mass(hp):
    plant = hp.plant
    assert plant.num_velocities() == 31
    assert plant.num_positions() == 31  # roll-pitch-yaw joints: minimal coordinates
    bodies = {plant.get_body(b).name() for b in plant.GetBodyIndices(hp.human)}
    assert SEGMENTS <= bodies
    # The only other body is the near-massless carrier of the spinal DoF.
    assert bodies - SEGMENTS == {"spine_slider"}
    mass = sum(plant.get_body(b).default_mass() for b in plant.GetBodyIndices(hp.human))
    assert mass == pytest.approx(75.3, abs=0.5)


def test_joints_are_the_papers(hp):
    plant = hp.plant
    dofs = {}
    for j in plant.GetJointIndices(hp.human):
        joint = plant.get_joint(j)
        dofs[joint.name()] = (joint.type_name(), joint.num_velocities())
    free = plant.GetJointByName("pelvis_free")
    assert (free.type_name(), free.num_velocities()) == ("rpy_floating", 6)
    expected = {
        "lumbosacral_L5S1": ("ball_rpy", 3), "lumbar_L4L5": ("ball_rpy", 3),
        "spinal_compression": ("prismatic", 1), "thoracolumbar_T12L1": ("ball_rpy", 3),
        "lower_neck_C7T1": ("universal", 2), "upper_neck_C0C1": ("ball_rpy", 3),
        "hip_l": ("ball_rpy", 3), "hip_r": ("ball_rpy", 3), "knee_l": ("revolute", 1),
        "knee_r": ("revolute", 1), "ankle_l": ("revolute", 1), "ankle_r": ("revolute", 1),
    }
    for name, kind in expected.items():
        assert dofs[name] == kind, name
    assert sum(n for _, n in expected.values()) + 6 == 31


def test_segment_masses_follow_de_leva():
    body = build_body()
    M = REFERENCE.mass_kg
    frac = {k: v[1] / 100 for k, v in DE_LEVA_1996_MALE.items()}
    s = body.segments
    assert s["thigh_l"].mass == pytest.approx(frac["thigh"] * M)
    assert s["lower_leg_r"].mass == pytest.approx(frac["shank"] * M)
    assert s["middle_torso"].mass == pytest.approx(frac["mpt"] * M)
    assert s["pelvis"].mass + s["lower_torso"].mass == pytest.approx(frac["lpt"] * M)
    assert s["neck"].mass + s["head"].mass == pytest.approx(frac["head"] * M)
    arms = 2 * (frac["upper_arm"] + frac["forearm"] + frac["hand"])
    assert s["upper_torso"].mass == pytest.approx((frac["upt"] + arms) * M)
    for seg in s.values():  # physically valid inertia: PD and triangle inequality
        ev = np.linalg.eigvalsh(seg.inertia_W)
        assert ev.min() > 0 and ev[0] + ev[1] >= ev[2] * (1 - 1e-9), seg.name


def test_sitting_height_is_the_papers():
    body = build_body()
    assert body.landmarks["vertex"][2] == pytest.approx(0.92, abs=0.005)


def test_marker_frames_exist(hp):
    for seg in ("pelvis", "trunk", "head", "knee_l", "knee_r"):
        hp.plant.GetFrameByName(f"{seg}_marker", hp.human)
    t8 = hp.plant.GetFrameByName("trunk_marker", hp.human)
    assert t8.body().name() == "upper_torso"


def test_sdf_on_disk_is_generated_from_the_anthropometry():
    body = build_body()
    d = model_directory()
    assert (d / HUMAN_SDF_NAME).read_text() == human_sdf(body)
    assert (d / HUMAN_CARDAN_SDF_NAME).read_text() == human_sdf(body, CARDAN_JOINTS)
    assert (d / SEAT_SDF_NAME).read_text() == seat_sdf(body)
    assert (d / "package.xml").is_file()


def test_the_packaged_text_gives_the_plant_the_url_gives():
    """The model is parsed from the packaged files' text (`packaged_sdf`,
    fast), not from their `package://` URLs: the same bodies, masses,
    inertias and joints either way."""
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    from ehm_drake.model.sdf_writer import PACKAGE_NAME, configure_parser, packaged_sdf

    def plant_of(load):
        plant = MultibodyPlant(0.001)
        parser = configure_parser(Parser(plant))
        for name in (HUMAN_SDF_NAME, SEAT_SDF_NAME):
            load(parser, name)
        plant.Finalize()
        ctx = plant.CreateDefaultContext()
        bodies = [plant.get_body(i) for i in plant.GetBodyIndices(plant.GetModelInstanceByName(
            "ehm_human"))]
        return ([(b.name(), b.CalcSpatialInertiaInBodyFrame(ctx).CopyToFullMatrix6().tobytes())
                 for b in bodies],
                [plant.get_joint(j).name() for j in plant.GetJointIndices()])

    by_text = plant_of(lambda p, n: p.AddModelsFromString(packaged_sdf(n), "sdf"))
    by_url = plant_of(lambda p, n: p.AddModels(url=f"package://{PACKAGE_NAME}/{n}"))
    assert by_text == by_url
    # The 12 segments and the spinal slider's 0.1 g link.
    assert len(by_text[0]) == 13 and ("spine_slider" in dict(by_text[0]))


@pytest.mark.parametrize("mass,stature", [(60.0, 1.62), (100.0, 1.90)])
def test_scaled_body(params, mass, stature):
    hp = add_seated_human(DiagramBuilder(), params, BodyMeasures(mass, stature))
    plant = hp.plant
    total = sum(plant.get_body(b).default_mass() for b in plant.GetBodyIndices(hp.human))
    assert total == pytest.approx(mass, abs=1e-3)  # + the 0.1 g spine slider
    body = hp.body
    sh = body.measures.resolved_sitting_height()
    assert body.landmarks["vertex"][2] == pytest.approx(0.92 * sh / 0.92, rel=0.01)
    # Seat adjusted to the occupant: pads at the scaled landmarks.
    assert body.seat.boxes["upper_pad"][0][2] == pytest.approx(
        body.landmarks["scapula_angle_skin"][2])


@pytest.mark.parametrize("variant, measures", [
    ("default", REFERENCE), ("no-integrator", REFERENCE),
    ("default", BodyMeasures(mass_kg=55.0, stature_m=1.55, sitting_height_m=0.82)),
    ("default", BodyMeasures(mass_kg=100.0, stature_m=1.92, sitting_height_m=1.00))])
def test_the_seat_is_touched_inside_its_parts_faces(params, variant, measures):
    """The seat's contact surfaces are half-spaces through its parts'
    faces (`sdf_writer.seat_sdf`): the same surface as the parts' boxes
    only while each body ellipsoid touches its part inside the face.  At
    rest every contact point lies at least 3 cm inside its face's edges
    (measured 40-169 mm; the closest, the lower back on its 10 cm pad,
    within 10 mm of the pad's middle), far beyond the millimetres the body
    moves in vibration; and each seat part is a half-space, touched on its
    face's plane."""
    from pydrake.geometry import HalfSpace

    from ehm_drake.diagram import build_diagram
    from ehm_drake.model.restraints import SEAT_PARTS
    from ehm_drake.simulation import static_equilibrium

    model = build_diagram(params, measures, variant=variant, guard=False, seat_forces=False)
    ctx, _ = static_equilibrium(model)
    pc = model.plant_context(ctx)
    inspector = model.hp.scene_graph.model_inspector()
    boxes = model.hp.body.seat.boxes
    assert all(isinstance(inspector.GetShape(gid), HalfSpace)
               for gid in model.hp.seat_geometries.values())
    results = model.plant.get_contact_results_output_port().Eval(pc)
    touched = set()
    for i in range(results.num_point_pair_contacts()):
        info = results.point_pair_contact_info(i)
        body = inspector.GetName(info.point_pair().id_A).split("::")[-1]
        part = inspector.GetName(info.point_pair().id_B).split("::")[-1]
        centre, size = boxes[part]
        normal = SEAT_PARTS[part][0]
        on_face = normal == 0
        p = info.contact_point()
        margin = np.min(size[on_face] / 2 - np.abs(p[on_face] - centre[on_face]))
        assert margin > 0.03, (body, part, margin)
        # On the face's plane: Drake puts the point between the two
        # surfaces in the ratio of their stiffnesses, the seat's 1e10 N/m
        # against the body's ~1e5 (depth x 1e-5, under 1e-7 m).
        face = centre @ normal + 0.5 * size @ normal
        assert abs(p @ normal - face) < 1e-6, (body, p)
        touched.add(body)
    # Every ellipsoid touches (the no-integrator body leaves its upper pad).
    assert len(touched) == (6 if variant == "no-integrator" else 7), touched


@pytest.mark.parametrize("measures,match", [
    (BodyMeasures(75.3, 176.0), "centimetres"),
    (BodyMeasures(0.075, 1.76), "outside"),
    (BodyMeasures(float("nan"), 1.76), "finite"),
    (BodyMeasures(75.3, 1.76, 1.2), "sitting_height"),
])
def test_bad_anthropometry_is_rejected(measures, match):
    with pytest.raises(ValueError, match=match):
        build_body(measures)


def test_cardan_rate_matrix_matches_drake():
    rng = np.random.default_rng(0)
    for _ in range(20):
        rpy = rng.uniform(-0.6, 0.6, 3)
        w = rng.standard_normal(3)
        expected = RollPitchYaw(rpy).CalcRpyDtFromAngularVelocityInParent(w)
        N = rpy_rate_matrices(rpy[None, :])[0]
        np.testing.assert_allclose(N @ w, expected, atol=1e-12)


def test_cardan_torque_mapping_conserves_power(hp):
    """f = N^T tau: the power of the generalized force on w equals the power
    of the gimbal torque on the angle rates."""
    from ehm_drake.systems.joints import _BallIndex

    layout = hp.layout
    rng = np.random.default_rng(1)
    q = rng.uniform(-0.5, 0.5, layout.num_rotational)
    v = rng.standard_normal(layout.num_rotational)
    tau = rng.standard_normal(layout.num_rotational)
    f = cardan_to_generalized(_BallIndex(layout), q, tau)
    b = layout.ball_triplets
    qdot = v.copy()
    qdot[b] = np.einsum("nij,nj->ni", rpy_rate_matrices(q[b]), v[b])
    assert f @ v == pytest.approx(tau @ qdot, rel=1e-12)


def test_the_sdf_folder_resolves_outside_the_checkout(tmp_path):
    """From another folder, `ehm_drake` is the installed package (not the checkout's
    source tree): its SDF folder must be a real folder holding package.xml."""
    import subprocess
    import sys
    from pathlib import Path

    out = subprocess.run(
        [sys.executable, "-c",
         "from ehm_drake.model.sdf_writer import model_directory; print(model_directory())"],
        cwd=tmp_path, capture_output=True, text=True, check=True).stdout.strip()
    folder = Path(out)
    assert (folder / "package.xml").is_file(), out
    assert (folder / "ehm_human_50th_male.sdf").is_file()


# ---------------------------------------------------------------------------
# Model extensions: the core calls their hooks, it names none
# ---------------------------------------------------------------------------


def test_the_candidate_effects_are_the_registered_extensions():
    from ehm_drake.gap.library.effects import EFFECT_NAMES, validate_effects
    from ehm_drake.model.extensions import extension_names, validate_extensions

    assert extension_names() == EFFECT_NAMES
    eff = {"seat_friction": {"mu": 0.5}, "visceral_mass": {}}
    assert validate_extensions(eff) == validate_effects(eff)


def test_a_new_extension_reaches_the_diagram_without_core_changes(params, monkeypatch):
    """A toy extension (a constant generalized force, the pads' restraints
    gated) enters through the hooks alone."""
    from pydrake.systems.framework import LeafSystem

    from ehm_drake.diagram import build_diagram
    from ehm_drake.model import extensions
    from ehm_drake.systems.seat import restraint_block

    class Push(LeafSystem):
        def __init__(self, nq, nv, f):
            super().__init__()
            self.DeclareVectorInputPort("state", nq + nv)
            self.DeclareVectorOutputPort("generalized_force", nv,
                                         lambda ctx, out: out.SetFromVector(f))

    class ConstantPush(extensions.ModelExtension):
        name = "constant_push"

        def add_force_systems(self, parts):
            layout = parts.hp.layout
            f = np.full(layout.nv, self.values["force"])
            return [parts.add_system("push", Push(layout.nq, layout.nv, f))]

        def restraint_options(self, params, points):
            return {"gated_parts": ("lower_pad",)}

    monkeypatch.setitem(extensions._REGISTRY, "constant_push", ConstantPush)

    def evaluate(effects):
        m = build_diagram(params, effects=effects)
        ctx = m.diagram.CreateDefaultContext()
        for port in ("seat_acceleration", "seat_displacement"):
            m.diagram.GetInputPort(port).FixValue(ctx, np.zeros(3))
        # What the plant receives (through the sum when an extension adds
        # a force system, straight from `ForceLaws` otherwise).
        force = m.plant.get_applied_generalized_force_input_port().Eval(m.plant_context(ctx))
        r = m.systems["shear_restraints"]
        gated = restraint_block(r.GetMyContextFromRoot(ctx).get_numeric_parameter(
            r.parameter_index).CopyToVector(), "contact_gated")
        return m, force, gated

    _, f0, g0 = evaluate({})
    m, f1, g1 = evaluate({"constant_push": {"force": 0.5}})
    assert "push" in m.systems and m.effects == {"constant_push": {"force": 0.5}}
    np.testing.assert_allclose(f1 - f0, 0.5, atol=1e-9)
    pads = [p.part == "lower_pad" for p in m.systems["shear_restraints"].points]
    assert np.array_equal(g1, np.where(pads, 1.0, 0.0)) and not np.any(g0)
