"""Robots by name, joint-angle coordinates, the CasADi kinematics against pinocchio, h(θ)."""

from __future__ import annotations

import functools
import shutil
from pathlib import Path

import casadi as ca
import coal
import numpy as np
import pinocchio as pin
import pytest

from optlight.errors import ProblemError, RobotError
from optlight.geometry import LightSphere, sphere_frame
from optlight.robot import SUPPORTED_ROBOTS, Robot, light_angles, light_residual, load_robot
from optlight.robot.catalogue import ROBOTS, example_robot_data_dir
from optlight.robot.kinematics import symbolic_frame_pose
from optlight.robot.loading import JointCoordinates, placement
from optlight.robot.urdf import find_package, resolve_mesh, unread_visual_meshes
from optlight.spec import RobotSpec, load_problem, problem_from_dict

N_CONFIGS = 200


@functools.cache
def robot(name: str) -> Robot:
    return load_robot(name)


def configurations(r: Robot, n: int = N_CONFIGS, seed: int = 0) -> np.ndarray:
    return r.random_configuration(np.random.default_rng(seed), n)


def pin_poses(r: Robot, thetas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    out = [r.light_pose(t) for t in thetas]
    return np.array([p for p, _ in out]), np.array([rot for _, rot in out])


@pytest.mark.parametrize("name", SUPPORTED_ROBOTS)
def test_casadi_kinematics_equals_pinocchio(name: str) -> None:
    r = robot(name)
    thetas = configurations(r)
    p_pin, r_pin = pin_poses(r, thetas)
    p_ca, r_ca = r.symbolic_light_pose.map(N_CONFIGS)(thetas.T)
    p_ca = np.array(p_ca).T
    r_ca = np.array(r_ca).reshape(3, N_CONFIGS, 3).transpose(1, 0, 2)  # [R_1 … R_N] side by side
    assert np.abs(p_ca - p_pin).max() < 1e-10
    assert np.abs(r_ca - r_pin).max() < 1e-10


@pytest.mark.parametrize("name", SUPPORTED_ROBOTS)
def test_casadi_jacobian_equals_pinocchio_frame_jacobian(name: str) -> None:
    """d a_L/dθ = J_v and d(R e_i)/dθ = J_ω × (R e_i) for the axes x_L and z_L (LOCAL_WORLD_ALIGNED)."""
    r = robot(name)
    theta = ca.SX.sym("theta", r.n)
    p, rot = r.symbolic_light_pose(theta)
    jac = ca.Function(
        "light_axes_jacobian",
        [theta],
        [ca.jacobian(p, theta), ca.jacobian(rot[:, 0], theta), ca.jacobian(rot[:, 2], theta)],
    )
    for t in configurations(r, N_CONFIGS, seed=1):
        jp, jx, jz = (np.array(m) for m in jac(t))
        j = r.light_jacobian(t)
        _, rot_pin = r.light_pose(t)
        assert np.abs(jp - j[:3]).max() < 1e-10
        assert np.abs(jx - np.cross(j[3:].T, rot_pin[:, 0]).T).max() < 1e-10
        assert np.abs(jz - np.cross(j[3:].T, rot_pin[:, 2]).T).max() < 1e-10


@pytest.mark.parametrize("name", SUPPORTED_ROBOTS)
def test_robot_attributes_are_consistent(name: str) -> None:
    r = robot(name)
    n = r.n
    assert len(r.joint_names) == n and r.model.nv == n
    for arr in (r.lower, r.upper, r.velocity_limit, r.acceleration_limit, r.jerk_limit, r.theta_ref):
        assert arr.shape == (n,)
    assert np.all(r.lower < r.upper)
    assert np.all(r.velocity_limit > 0) and np.all(r.acceleration_limit > 0) and np.all(r.jerk_limit > 0)
    # never faster than the URDF allows
    assert np.all(r.velocity_limit <= np.asarray(r.model.velocityLimit) + 1e-12)
    assert r.within_limits(r.theta_ref)
    assert r.model.frames[r.light_frame_id].name == "light"
    assert r.light_jacobian(r.theta_ref).shape == (6, n)
    thetas = configurations(r, 20)
    back = r.from_pin(r.to_pin(thetas))
    assert np.allclose(np.cos(back), np.cos(thetas)) and np.allclose(np.sin(back), np.sin(thetas))
    assert np.allclose(r.to_pin(back), r.to_pin(thetas))


def test_continuous_joints_are_cos_sin_with_two_turn_limits() -> None:
    r = robot("kinova")
    assert r.model.nq == 9 and r.n == 6
    continuous = [i for i, k in enumerate(r.joint_kinds) if k.startswith("JointModelRUB")]
    assert continuous == [0, 3, 5]
    assert np.allclose(r.lower[continuous], -2 * np.pi) and np.allclose(r.upper[continuous], 2 * np.pi)
    theta = np.array([2.5, 2.0, 3.0, -3.0, 3.0, 0.3])
    q = r.to_pin(theta)
    j1 = r.model.joints[r.model.getJointId(r.joint_names[0])]
    assert np.allclose(q[j1.idx_q : j1.idx_q + 2], [np.cos(2.5), np.sin(2.5)])
    assert np.allclose(r.from_pin(q), theta)
    # θ and θ + 2π are the same pose for a continuous joint
    shifted = theta + np.array([2 * np.pi, 0, 0, 0, 0, 0])
    assert np.allclose(r.light_pose(shifted)[0], r.light_pose(theta)[0])


def test_panda_fingers_are_locked_and_reference_is_the_srdf_default() -> None:
    r = robot("panda")
    assert r.n == 7 and "panda_finger_joint1" not in r.joint_names
    assert np.allclose(r.theta_ref, [0, -0.785398, 0, -2.35619, 0, 1.5707, 0.785398])
    assert np.allclose(r.acceleration_limit, ROBOTS["panda"].acceleration_limit)


def test_flange_z_points_out_of_the_tool() -> None:
    """kinova and z1 tool frames have +x out of the tool: their flange is turned so +z is."""
    for name in ("kinova", "z1"):
        r = robot(name)
        tool = r.model.frames[r.model.frames[r.flange_frame_id].parentFrame].name
        for t in configurations(r, 5):
            assert np.allclose(r.frame_pose("flange", t).rotation[:, 2], r.frame_pose(tool, t).rotation[:, 0])
    r = robot("panda")
    t = r.theta_ref
    assert np.allclose(r.frame_pose("flange", t).homogeneous, r.frame_pose("panda_hand_tcp", t).homogeneous)


@pytest.mark.parametrize("name", SUPPORTED_ROBOTS)
def test_no_link_of_the_hand_stands_in_the_beam(name: str) -> None:
    """The geometry carried with the light (its joint's collision shapes, as surfaces) has no point in
    the cone of half-angle 30° ahead of the light (the Panda's fingertips stand 43° off its axis), so
    no posture puts it in the middle of the beam: the z1's gripper reached 0.149 m ahead of ``gripperStator``, where
    its flange was, and blocked the beam at every capture."""
    from optlight.environment.collision import _surface

    r = robot(name)
    joint = r.model.frames[r.light_frame_id].parentJoint
    geom = r.geometry_model("collision")
    theta = configurations(r, 1)[0]
    pin.forwardKinematics(r.model, r.data, r.to_pin(theta))
    position, rotation = r.light_pose(theta)
    for obj in geom.geometryObjects:
        if obj.parentJoint != joint:
            continue
        surface = _surface(obj.geometry, obj.name).apply_transform((r.data.oMi[joint] * obj.placement).homogeneous)
        offset = np.asarray(surface.vertices) - position
        along = offset @ rotation[:, 2]
        across = np.linalg.norm(offset - along[:, None] * rotation[:, 2], axis=1)
        assert not np.any((along > 0.0) & (across < along * np.tan(np.radians(30.0)))), (name, obj.name)


def test_base_placement_moves_everything_consistently() -> None:
    base = RobotSpec(name="panda", base_position_m=(0.3, -0.2, 0.1), base_rpy_deg=(5.0, -10.0, 30.0))
    moved, ref = load_robot(base), robot("panda")
    t_wb = placement(base.base_position_m, base.base_rpy_deg)
    for t in configurations(ref, 10):
        expect = t_wb * ref.frame_pose("light", t)
        p, rot = moved.light_pose(t)
        assert np.allclose(p, expect.translation) and np.allclose(rot, expect.rotation)
        p_ca, r_ca = moved.symbolic_light_pose(t)
        assert np.allclose(np.array(p_ca).ravel(), p) and np.allclose(np.array(r_ca), rot)
        assert np.allclose(moved.frame_pose("panda_link0", t).homogeneous, t_wb.homogeneous)
        jac_ref, jac = ref.light_jacobian(t), moved.light_jacobian(t)
        assert np.allclose(jac[:3], t_wb.rotation @ jac_ref[:3]) and np.allclose(
            jac[3:], t_wb.rotation @ jac_ref[3:]
        )
    geom = moved.geometry_model("collision")
    data = moved.model.createData()
    gdata = geom.createData()
    pin.framesForwardKinematics(moved.model, data, moved.to_pin(moved.theta_ref))
    pin.updateGeometryPlacements(moved.model, data, geom, gdata)
    link0 = next(i for i, g in enumerate(geom.geometryObjects) if g.name.startswith("panda_link0"))
    assert np.allclose(gdata.oMg[link0].translation, t_wb.translation, atol=0.1)


def test_light_offset_and_rotation_relative_to_the_flange() -> None:
    spec = RobotSpec(name="ur5", light_offset_m=(0.01, -0.02, 0.05), light_rpy_deg=(0.0, 20.0, 45.0))
    r, ref = load_robot(spec), robot("ur5")
    offset = placement(spec.light_offset_m, spec.light_rpy_deg)
    for t in configurations(r, 10):
        expect = ref.frame_pose("tool0", t) * offset
        p, rot = r.light_pose(t)
        assert np.allclose(p, expect.translation) and np.allclose(rot, expect.rotation)
        p_ca, _ = r.symbolic_light_pose(t)
        assert np.allclose(np.array(p_ca).ravel(), p)


def test_unknown_robot_lists_the_supported_ones() -> None:
    with pytest.raises(RobotError) as err:
        load_robot("r2d2")
    for name in SUPPORTED_ROBOTS:
        assert name in str(err.value)


def test_unknown_frame_lists_the_frames() -> None:
    with pytest.raises(RobotError) as err:
        load_robot(RobotSpec(name="panda", frame="nose"))
    assert (
        "'nose'" in str(err.value) and "panda_hand_tcp" in str(err.value) and "panda_link8" in str(err.value)
    )
    assert str(err.value).startswith("robot.frame:")
    problem = problem_from_dict({"robot": {"name": "panda", "frame": "nose"}})
    with pytest.raises(ProblemError) as perr:
        load_robot(problem)
    assert perr.value.key == "robot.frame" and "panda_link8" in str(perr.value)


def test_package_lookup_follows_ros_conventions(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """package://NAME: a folder NAME in (or named by) the URDF's folder or any folder above it, at any
    depth; then ROS_PACKAGE_PATH, also a package folder a few levels below an entry."""
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    package = tmp_path / "ws" / "src" / "cell_description"
    urdf = package / "urdf" / "a" / "b" / "c" / "arm.urdf"
    urdf.parent.mkdir(parents=True)
    (package / "meshes").mkdir()
    (package / "package.xml").write_text("<package><name>cell_description</name></package>")
    mesh = package / "meshes" / "link.stl"
    mesh.write_bytes(b"solid x\nendsolid x\n")
    assert find_package("cell_description", urdf) == package  # five folders up
    assert resolve_mesh("package://cell_description/meshes/link.stl", urdf) == mesh
    assert resolve_mesh("package://cell_description/meshes/none.stl", urdf) is None
    assert resolve_mesh("../../../../meshes/link.stl", urdf) == urdf.parent / "../../../../meshes/link.stl"
    assert resolve_mesh(f"file://{mesh}", urdf) == mesh
    elsewhere = tmp_path / "other" / "arm.urdf"
    elsewhere.parent.mkdir()
    assert find_package("cell_description", elsewhere) is None
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ws"))  # the package is 2 levels below
    assert find_package("cell_description", elsewhere) == package
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(package))  # the entry is the package itself
    assert find_package("cell_description", elsewhere) == package


def _same_visuals(unread: pin.GeometryModel, read: pin.GeometryModel) -> None:
    """The visual objects as pinocchio reads them, but for the mesh data: names, joints, frames,
    placements, files, scales, colours, and the primitives' shapes."""
    assert [g.name for g in unread.geometryObjects] == [g.name for g in read.geometryObjects]
    for a, b in zip(unread.geometryObjects, read.geometryObjects, strict=True):
        assert (a.parentJoint, a.parentFrame, a.meshPath, a.overrideMaterial) == (
            b.parentJoint,
            b.parentFrame,
            b.meshPath,
            b.overrideMaterial,
        ), a.name
        assert a.placement.isApprox(b.placement, 1e-14), a.name
        assert np.array_equal(a.meshScale, b.meshScale) and np.array_equal(a.meshColor, b.meshColor), a.name
        if b.geometry.getObjectType() == coal.OT_BVH:  # a mesh: not read, an empty BVH (a viewer reads the file)
            assert isinstance(a.geometry, coal.BVHModelBase) and a.geometry.num_vertices == 0, a.name
        else:
            assert a.geometry.getNodeType() == b.geometry.getNodeType(), a.name
            assert a.geometry.saveToString() == b.geometry.saveToString(), a.name


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_visual_meshes_unread_are_pinocchios_objects_but_for_the_mesh_data(name: str) -> None:
    """The preview takes the visual meshes' files, not their data: read by pinocchio as the
    reference, every robot's visual objects are the same, the locked panda fingers reduced away."""
    r = robot(name)
    _same_visuals(r.geometry_model("visual"), r.geometry_model("visual", read_meshes=True))


def test_visual_meshes_unread_of_a_user_urdf(tmp_path: Path) -> None:
    """Two visuals on a link, a scaled mesh under a named material, a primitive with its own colour
    and a mesh on a fixed child link: as pinocchio reads them."""
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "tri.obj").write_text("v 0 0 0\nv 0.01 0 0\nv 0 0.01 0\nf 1 2 3\n")
    mesh = '<mesh filename="{}" scale="2 3 4"/>'
    (tmp_path / "arm.urdf").write_text(
        '<robot name="arm"><material name="red"><color rgba="1 0 0 1"/></material>'
        '<link name="base"/><link name="upper">'
        '<visual><origin xyz="0 0 0.1" rpy="0.1 0.2 0.3"/><geometry>'
        + mesh.format("meshes/tri.obj")
        + '</geometry><material name="red"/></visual>'
        '<visual><geometry><box size="0.1 0.2 0.3"/></geometry>'
        '<material name="blue"><color rgba="0 0 1 0.5"/></material></visual>'
        '</link><link name="tool"><visual><geometry>'
        + mesh.format(f"file://{tmp_path}/meshes/tri.obj")
        + "</geometry></visual></link>"
        '<joint name="j" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        '<joint name="f" type="fixed"><parent link="upper"/><child link="tool"/>'
        '<origin xyz="0.2 0 0"/></joint></robot>'
    )
    full = pin.buildModelFromUrdf(str(tmp_path / "arm.urdf"))
    read = pin.buildGeomFromUrdf(full, str(tmp_path / "arm.urdf"), pin.GeometryType.VISUAL, package_dirs=[str(tmp_path)])
    unread = unread_visual_meshes(full, tmp_path / "arm.urdf")
    assert [g.name for g in read.geometryObjects] == ["upper_0", "upper_1", "tool_0"]
    _same_visuals(unread, read)
    assert unread.geometryObjects[0].meshScale.tolist() == [2.0, 3.0, 4.0]


def test_example_robot_data_urdf_as_a_user_urdf_resolves_four_folders_up() -> None:
    """kinova's meshes are package://example-robot-data/…, four folders above its URDF."""
    urdf = example_robot_data_dir() / "example-robot-data/robots/kinova_description/robots/kinova.urdf"
    problem = problem_from_dict(
        {"robot": {"name": "my kinova", "urdf": str(urdf), "frame": "j2s6s200_end_effector"}}
    )
    r = load_robot(problem)
    assert r.n == 6 and len(r.geometry_model("visual").geometryObjects) > 0


def test_user_urdf_relative_to_the_problem_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    source = (
        example_robot_data_dir()
        / "example-robot-data"
        / "robots"
        / "ur_description"
        / "urdf"
        / "ur5_robot.urdf"
    )
    (tmp_path / "arms").mkdir()
    shutil.copy(source, tmp_path / "arms" / "my_ur5.urdf")
    problem_file = tmp_path / "cell.toml"
    problem_file.write_text('[robot]\nname = "my arm"\nurdf = "arms/my_ur5.urdf"\nframe = "tool0"\n')
    # its meshes are package://example-robot-data/…: not above the copy, so only ROS_PACKAGE_PATH finds them
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    with pytest.raises(ProblemError, match="package://example-robot-data") as err:
        load_robot(load_problem(problem_file))
    assert err.value.key == "robot.urdf"
    monkeypatch.setenv("ROS_PACKAGE_PATH", f"/nonexistent:{example_robot_data_dir()}")
    r = load_robot(load_problem(problem_file))
    assert len(r.geometry_model("visual").geometryObjects) > 0
    assert r.name == "my arm" and r.n == 6
    assert np.allclose(r.theta_ref, 0.5 * (r.lower + r.upper))
    for t in configurations(r, 5):
        assert np.allclose(r.light_pose(t)[0], robot("ur5").light_pose(t)[0])
    with pytest.raises(RobotError, match="frame"):
        load_robot(RobotSpec(urdf=str(source)))


def test_light_residual_numeric_and_symbolic() -> None:
    r = robot("xarm7")
    rng = np.random.default_rng(3)
    t_true = r.random_configuration(rng)
    p, rot = r.light_pose(t_true)
    centre = p + 0.4 * rot[:, 2]
    sphere = LightSphere(centre, 0.4, sphere_frame(centre, centre + np.array([0.0, -1.0, 0.0])))
    assert np.abs(light_residual(r, sphere, t_true)).max() < 1e-12
    # aimed at O but 0.1 m too far away: h = (0, 0, 0.1); aimed 90° off: h_z = −b
    farther = LightSphere(p + 0.5 * rot[:, 2], 0.4, sphere.rotation)
    assert np.allclose(light_residual(r, farther, t_true), [0.0, 0.0, 0.1])
    beside = LightSphere(p + 0.4 * rot[:, 0], 0.4, sphere.rotation)
    assert np.allclose(light_residual(r, beside, t_true), [0.4, 0.0, -0.4])
    theta = ca.SX.sym("theta", r.n)
    h_fun = ca.Function("h", [theta], [light_residual(r, sphere, theta)])
    theta_mx = ca.MX.sym("theta", r.n)
    h_mx = ca.Function("h", [theta_mx], [light_residual(r, sphere, theta_mx)])
    for t in configurations(r, 20, seed=4):
        h = light_residual(r, sphere, t)
        assert h.shape == (3,)
        assert np.allclose(np.array(h_fun(t)).ravel(), h, atol=1e-12)
        assert np.allclose(np.array(h_mx(t)).ravel(), h, atol=1e-12)


def test_light_angles_follow_the_sphere_convention() -> None:
    problem = problem_from_dict({})
    r = load_robot(problem)
    sphere = LightSphere.from_problem(problem)
    zenith, azimuth = light_angles(r, sphere, r.theta_ref)
    z_ref, a_ref = sphere.angles(r.light_pose(r.theta_ref)[0])
    assert np.isclose(zenith, z_ref) and np.isclose(azimuth, a_ref)


def _chain_urdf(rng: np.random.Generator) -> str:
    """A URDF chain with every joint type optlight handles, unaligned axes included."""
    specs = [
        ("revolute", "0.267 0.535 0.802"),  # unaligned revolute
        ("continuous", "1 0 0"),
        ("prismatic", "0.6 0 0.8"),  # unaligned prismatic
        ("revolute", "0 1 0"),
        ("continuous", "0 0.6 0.8"),  # unaligned continuous
        ("prismatic", "0 0 1"),
        ("continuous", "0 0 1"),
    ]
    links = "".join(f'<link name="l{k}"/>' for k in range(len(specs) + 1))
    joints = ""
    for k, (kind, axis) in enumerate(specs):
        xyz = " ".join(f"{x:.3f}" for x in rng.normal(size=3) * 0.2)
        rpy = " ".join(f"{x:.3f}" for x in rng.uniform(-3, 3, size=3))
        limit = '<limit lower="-2" upper="2" effort="1" velocity="1"/>' if kind != "continuous" else ""
        joints += (
            f'<joint name="j{k}" type="{kind}"><parent link="l{k}"/><child link="l{k + 1}"/>'
            f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>{limit}</joint>'
        )
    return f'<robot name="chain">{links}{joints}</robot>'


def test_casadi_kinematics_handles_every_joint_type() -> None:
    """Unaligned revolute/prismatic/continuous axes and continuous joints, from a URDF."""
    rng = np.random.default_rng(7)
    model = pin.buildModelFromXML(_chain_urdf(rng))
    kinds = {j.shortname() for j in model.joints[1:]}
    assert {"JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned", "JointModelRUBX"} <= kinds
    assert "JointModelRevoluteUnboundedUnaligned" in kinds
    tip = model.addFrame(pin.Frame("tip", model.njoints - 1, pin.SE3.Random(), pin.FrameType.OP_FRAME))
    coords = JointCoordinates(model)
    assert model.nq == 10 and model.nv == 7
    fk = symbolic_frame_pose(model, tip)
    data = model.createData()
    for theta in rng.uniform(-3, 3, size=(50, 7)):
        pin.framesForwardKinematics(model, data, coords.to_pin(theta))
        p, rot = fk(theta)
        assert np.abs(np.array(p).ravel() - data.oMf[tip].translation).max() < 1e-12
        assert np.abs(np.array(rot) - data.oMf[tip].rotation).max() < 1e-12


def test_every_robot_name_the_problem_files_accept_loads() -> None:
    assert set(ROBOTS) == set(SUPPORTED_ROBOTS)


def test_published_limits_and_problem_overrides() -> None:
    from optlight.spec import load_problem, problem_from_dict

    panda = robot("panda")  # Franka's published values (docs/design.md §7)
    np.testing.assert_array_equal(panda.acceleration_limit, [15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])
    np.testing.assert_array_equal(panda.jerk_limit, 7500.0)
    np.testing.assert_allclose(robot("ur10").velocity_limit[:2], np.deg2rad(120.0))  # below the URDF's
    data = load_problem("default").to_dict()
    data["robot"].update(jerk_limit=[1.0, 2, 3, 4, 5, 6, 7], acceleration_limit=3.0)
    overridden = load_robot(problem_from_dict(data))
    np.testing.assert_array_equal(overridden.jerk_limit, [1, 2, 3, 4, 5, 6, 7])
    np.testing.assert_array_equal(overridden.acceleration_limit, 3.0)
    data["robot"].update(jerk_limit=[1.0, 2.0])
    with pytest.raises(RobotError, match=r"robot.jerk_limit: 2 values for the 7 joints"):
        load_robot(problem_from_dict(data))
    # a robot without a published jerk: the acceleration limit reached in DEFAULT_JERK_RAMP_S
    from optlight.robot.catalogue import DEFAULT_JERK_RAMP_S

    z1 = robot("z1")
    np.testing.assert_allclose(z1.jerk_limit, z1.acceleration_limit / DEFAULT_JERK_RAMP_S)
