"""A URDF robot and its declaration: which joints carry torque sensors, where the six-axis FT
sensor sits, the base (floating on a test rig's mount springs, or fixed), gravity.

Declared in a small TOML (``robots/quadruped_leg.toml``)::

    urdf = "quadruped_leg.urdf"       # relative to the TOML
    base = "floating"                 # or "fixed": held at mount.pose_*
    torque_sensed = ["hip_abd", "hip_flex", "knee"]   # default: every joint
    ft_frame = "ft_sensor"            # a URDF link (or joint) rigidly fixed to the base
    [mount]  pose_xyz, pose_rpy, stiffness (6), damping (6)   # the rig (simulation)

or given as a bare ``leg.urdf`` (every joint sensed, the FT sensor at the base link, floating).
The pinocchio model always has a free-flyer root (a fixed base is the free-flyer held at its
mount pose: its six rows carry the FT wrench). ``continuous`` joints are read as revolute (an
angle, not pinocchio's (cos, sin) pair). Joint types other than revolute/continuous/prismatic/
fixed are refused, naming the joint.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from userio.errors import InputError

SUPPORTED_JOINTS = ("revolute", "continuous", "prismatic", "fixed")


def rpy_matrix(rpy) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) (URDF's fixed-axis roll-pitch-yaw)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


@dataclass(frozen=True)
class Shape:
    """One collision solid of a link, in the link's frame: kind box|cylinder|sphere|capsule|mesh,
    ``size`` (box: 3 edge lengths; cylinder/capsule: radius, length along local z; sphere: radius;
    mesh: scale ×3), its pose (R, p) in the link frame, and the mesh file."""

    kind: str
    size: tuple
    rotation: np.ndarray
    origin: np.ndarray
    mesh_path: str | None = None


@dataclass
class SpatialRobot:
    """A URDF robot with its sensors. ``model`` is the pinocchio model (free-flyer root)."""

    name: str
    urdf_path: Path
    urdf_text: str
    floating: bool
    joint_names: tuple            # movable joints in pinocchio's order (= log and v rows)
    sensed: tuple                 # bool per joint
    ft_frame: str
    gravity_m_per_s2: float = 9.81
    mount_xyz: np.ndarray = field(default_factory=lambda: np.zeros(3))
    mount_rpy: np.ndarray = field(default_factory=lambda: np.zeros(3))
    mount_stiffness: np.ndarray = field(default_factory=lambda: np.array([2e4] * 3 + [800.0] * 3))
    mount_damping: np.ndarray = field(default_factory=lambda: np.array([150.0] * 3 + [4.0] * 3))
    shapes: dict = field(default_factory=dict)    # URDF link name → [Shape]
    source: str = ""
    _model: object = None
    model_uncertainty: object | None = None   # declared ModelUncertainty (estimator.model)
    identification: dict | None = None        # the [identification] table of an identified file

    # ------------------------------------------------------------------ pinocchio
    @property
    def model(self):
        if self._model is None:
            self._model = build_model(self.urdf_text, self.source or str(self.urdf_path),
                                      self.gravity_m_per_s2)
        return self._model

    def with_model(self, model) -> "SpatialRobot":
        """The same robot on another pinocchio model (other inertial parameters)."""
        return replace(self, _model=model)

    def with_base(self, floating: bool) -> "SpatialRobot":
        return replace(self, floating=floating)

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def nv(self) -> int:
        return 6 + self.n_joints

    @property
    def nq(self) -> int:
        return 7 + self.n_joints

    def mount_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(R, p) of the base at rest (world)."""
        return rpy_matrix(self.mount_rpy), np.asarray(self.mount_xyz, float)

    def mount_quaternion(self) -> np.ndarray:
        """The rest orientation as a quaternion (x, y, z, w)."""
        return quat_from_matrix(self.mount_pose()[0])

    def rest_q(self) -> np.ndarray:
        """q = [p, quat(x, y, z, w), joints = 0] at the mount pose."""
        return np.r_[self.mount_xyz, self.mount_quaternion(), np.zeros(self.n_joints)]

    def ft_placement(self) -> tuple[np.ndarray, np.ndarray]:
        """(R_bs, p_bs): the FT sensor frame in the base frame."""
        model = self.model
        fid = model.getFrameId(self.ft_frame)
        M = model.frames[fid].placement
        return np.array(M.rotation), np.array(M.translation)


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w), w ≥ 0, of a rotation matrix."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(R).as_quat()
    return q if q[3] >= 0 else -q


def _parse_urdf(text: str, source: str):
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise InputError(f"{source}: not a readable URDF: {exc}") from None
    if root.tag != "robot":
        raise InputError(f"{source}: not a URDF: the root element is <{root.tag}>, expected <robot>")
    return root


def _floats(text, n, where):
    try:
        vals = [float(v) for v in str(text).split()]
    except ValueError:
        vals = []
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise InputError(f"{where}: expected {n} numbers, got {text!r}")
    return np.array(vals)


def _origin(elem, where):
    o = elem.find("origin") if elem is not None else None
    if o is None:
        return np.eye(3), np.zeros(3)
    return (rpy_matrix(_floats(o.get("rpy", "0 0 0"), 3, f"{where} <origin rpy>")),
            _floats(o.get("xyz", "0 0 0"), 3, f"{where} <origin xyz>"))


def _resolve_mesh(filename: str, urdf_path: Path, where: str) -> str:
    """A mesh file name relative to the URDF, ``file://`` or ``package://NAME/…`` (NAME found
    among the URDF's parent directories)."""
    if filename.startswith("file://"):
        p = Path(filename[7:])
    elif filename.startswith("package://"):
        pkg, _, rest = filename[10:].partition("/")
        p = None
        for d in [urdf_path.parent, *urdf_path.parents]:
            if d.name == pkg:
                p = d / rest
                break
            if (d / pkg).is_dir():
                p = d / pkg / rest
                break
        if p is None:
            raise InputError(f"{where}: mesh {filename!r}: package '{pkg}' not found above {urdf_path}")
    else:
        p = urdf_path.parent / filename
    if not p.is_file():
        raise InputError(f"{where}: mesh file {p} not found")
    return str(p)


def parse_shapes(root, urdf_path: Path, source: str) -> dict:
    """URDF link name → [Shape] from its <collision> elements (errors name the link)."""
    out = {}
    for link in root.findall("link"):
        name = link.get("name")
        shapes = []
        for k, col in enumerate(link.findall("collision")):
            where = f"{source}: link '{name}' <collision> {k + 1}"
            R, p = _origin(col, where)
            geom = col.find("geometry")
            if geom is None or len(geom) == 0:
                raise InputError(f"{where}: missing <geometry>")
            g = geom[0]
            if g.tag == "box":
                size = tuple(_floats(g.get("size"), 3, f"{where} <box size>"))
            elif g.tag in ("cylinder", "capsule"):
                size = (float(_floats(g.get("radius"), 1, f"{where} <{g.tag} radius>")[0]),
                        float(_floats(g.get("length"), 1, f"{where} <{g.tag} length>")[0]))
            elif g.tag == "sphere":
                size = (float(_floats(g.get("radius"), 1, f"{where} <sphere radius>")[0]),)
            elif g.tag == "mesh":
                size = tuple(_floats(g.get("scale", "1 1 1"), 3, f"{where} <mesh scale>"))
                shapes.append(Shape("mesh", size, R, p, _resolve_mesh(g.get("filename", ""), urdf_path, where)))
                continue
            else:
                raise InputError(f"{where}: unsupported geometry <{g.tag}> (box, cylinder, sphere, "
                                 f"capsule or mesh)")
            if any(not (s > 0) for s in size):
                raise InputError(f"{where}: <{g.tag}> dimensions must be > 0, got {size}")
            shapes.append(Shape(g.tag, size, R, p))
        out[name] = shapes
    return out


def _prepare_urdf(root, source: str) -> str:
    """The URDF text pinocchio reads: continuous joints as revolute (one angle, no limits
    needed), every joint type checked."""
    for j in root.findall("joint"):
        kind = j.get("type")
        if kind not in SUPPORTED_JOINTS:
            raise InputError(f"{source}: joint '{j.get('name')}': type '{kind}' is not supported "
                             f"(revolute, continuous, prismatic, fixed)")
        if kind == "continuous":
            j.set("type", "revolute")
            if j.find("limit") is None:
                ET.SubElement(j, "limit", lower="-1e6", upper="1e6", effort="1e6", velocity="1e6")
        if j.find("parent") is None or j.find("child") is None:
            raise InputError(f"{source}: joint '{j.get('name')}': missing <parent> or <child>")
    return ET.tostring(root, encoding="unicode")


def build_model(urdf_text: str, source: str, gravity: float = 9.81):
    """The pinocchio model of the URDF on a free-flyer root, gravity (0, 0, −g)."""
    import pinocchio as pin

    try:
        model = pin.buildModelFromXML(urdf_text, pin.JointModelFreeFlyer())
    except (RuntimeError, ValueError) as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{source}: pinocchio cannot build the model: {msg}") from None
    model.gravity.linear = np.array([0.0, 0.0, -float(gravity)])
    for j in range(2, model.njoints):
        if model.joints[j].nv != 1 or model.joints[j].nq != 1:
            raise InputError(f"{source}: joint '{model.names[j]}': only one-axis joints are supported")
    return model


def _collision_overrides(items, path: Path) -> dict:
    """``[[collision]]`` tables (validated, userio.schema.robot.Collision): link → [Shape]
    replacing the URDF's solids of that link (kind "none": no geometry)."""
    out = {}
    for i, c in enumerate(items, start=1):
        shapes = out.setdefault(c.link, [])
        if c.kind == "none":
            continue
        size = tuple(c.size) if c.size is not None else (1.0, 1.0, 1.0)
        mesh = None
        if c.kind == "mesh":
            mesh = path.parent / c.mesh
            if not mesh.is_file():
                raise InputError(f"{path}: collision[{i}].mesh: file {mesh} not found")
            mesh = str(mesh)
        shapes.append(Shape(c.kind, size, rpy_matrix(np.asarray(c.rpy, float)),
                            np.asarray(c.xyz, float), mesh))
    return out


def load_spatial_robot(path) -> SpatialRobot:
    """A robot declaration TOML (naming a URDF; userio.schema.robot.SpatialRobotFile) or a bare
    ``.urdf`` with the defaults."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if path.suffix.lower() == ".urdf":
        return robot_from_urdf(path)
    from userio.files import read_toml
    from userio.schema import parse
    from userio.schema.robot import SpatialRobotFile

    file = parse(SpatialRobotFile, read_toml(path), path)
    urdf = (path.parent / file.urdf) if not Path(file.urdf).is_absolute() else Path(file.urdf)
    if not urdf.is_file():
        raise InputError(f"{path}: urdf: file {urdf} not found")
    m = file.mount
    robot = robot_from_urdf(
        urdf, name=file.name or path.stem, floating=file.base == "floating",
        sensed_names=file.torque_sensed, ft_frame=file.ft_frame, gravity=file.gravity_m_per_s2,
        mount_xyz=np.asarray(m.pose_xyz, float), mount_rpy=np.asarray(m.pose_rpy, float),
        stiffness=np.asarray(m.stiffness, float), damping=np.asarray(m.damping, float),
        declaration=str(path), collision=_collision_overrides(file.collision, path))
    if file.model_uncertainty is None and file.identification is None:
        return robot
    from types import SimpleNamespace

    from estimator import inertial
    from estimator.spatial import inertial as spatial_inertial
    from estimator.spatial.tree import tree_from_model

    names = spatial_inertial.parameter_names(tree_from_model(robot.model, str(urdf)).body_names)
    theta = spatial_inertial.parameters_of(robot.model)     # what UrdfModel(robot) states
    view = SimpleNamespace(parameter_names=names, parameters=lambda: theta)
    return inertial.read_tables(robot, file, str(path), model=view)


def robot_from_urdf(urdf_path, *, name=None, floating=True, sensed_names=None, ft_frame=None,
                    gravity=9.81, mount_xyz=(0, 0, 0), mount_rpy=(0, 0, 0), stiffness=None,
                    damping=None, declaration: str | None = None,
                    collision: dict | None = None) -> SpatialRobot:
    urdf_path = Path(urdf_path)
    source = str(urdf_path)
    try:
        text = urdf_path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{source}: cannot read: {exc}") from None
    root = _parse_urdf(text, source)
    shapes = parse_shapes(root, urdf_path, source)
    model = build_model(_prepare_urdf(root, source), source, gravity)
    joints = tuple(model.names[j] for j in range(2, model.njoints))
    if not joints:
        raise InputError(f"{source}: the URDF has no movable joint")
    where = declaration or source
    for link, solids in (collision or {}).items():          # the declaration's overrides
        if link not in shapes:
            from userio.errors import nearest
            raise InputError(f"{where}: collision: no link '{link}' in {source}{nearest(link, list(shapes))}")
        shapes[link] = solids
    if sensed_names is None:
        sensed = tuple(True for _ in joints)
    else:
        for s in sensed_names:
            if s not in joints:
                from userio.errors import nearest
                raise InputError(f"{where}: torque_sensed: joint '{s}' is not a movable joint of "
                                 f"{source}{nearest(s, joints)} (joints: {', '.join(joints)})")
        sensed = tuple(j in sensed_names for j in joints)
    base_link = root_link(root)
    ft = ft_frame or base_link
    if not model.existFrame(ft):
        from userio.errors import nearest
        names = [fr.name for fr in model.frames if fr.name not in ("universe", "root_joint")]
        raise InputError(f"{where}: ft_frame: no frame '{ft}' in {source}{nearest(ft, names)}")
    fr = model.frames[model.getFrameId(ft)]
    if fr.parentJoint != 1:
        raise InputError(f"{where}: ft_frame: '{ft}' moves with joint '{model.names[fr.parentJoint]}'; "
                         f"the FT sensor must be fixed to the base link '{base_link}'")
    kw = {}
    if stiffness is not None:
        kw["mount_stiffness"] = np.asarray(stiffness, float)
    if damping is not None:
        kw["mount_damping"] = np.asarray(damping, float)
    return SpatialRobot(name=name or root.get("name") or urdf_path.stem, urdf_path=urdf_path,
                        urdf_text=_prepare_urdf(root, source), floating=bool(floating),
                        joint_names=joints, sensed=sensed, ft_frame=ft,
                        gravity_m_per_s2=float(gravity), mount_xyz=np.asarray(mount_xyz, float),
                        mount_rpy=np.asarray(mount_rpy, float), shapes=shapes, source=source,
                        _model=model, **kw)


def root_link(root) -> str:
    """The URDF's root link: the one that is no joint's child."""
    children = {j.find("child").get("link") for j in root.findall("joint")}
    roots = [l.get("name") for l in root.findall("link") if l.get("name") not in children]
    if len(roots) != 1:
        raise InputError(f"URDF: expected one root link (no joint's child), found {roots}")
    return roots[0]


def is_spatial_robot_file(path) -> bool:
    """A ``.urdf``, or a TOML with a top-level ``urdf`` key: a spatial robot."""
    path = Path(path)
    if path.suffix.lower() == ".urdf":
        return True
    if path.suffix.lower() != ".toml" or not path.is_file():
        return False
    try:
        from userio.files import read_toml

        return "urdf" in read_toml(path)
    except InputError:
        return False
