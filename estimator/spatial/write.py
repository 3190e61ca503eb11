"""Writing a URDF robot with other inertial parameters: the URDF with each body's inertia, and its
declaration TOML with an [identification] table (what ``torquebench identify`` writes for the
planar robot through ``estimator.inertial.robot_toml``).

A body (estimator.spatial.tree) is a URDF link with the links fixed to it merged; its identified
inertia goes on its own link (origin at the centre of mass, axes of the link frame, I_c about the
centre of mass) and the links fixed to it lose their <inertial> (their mass is in the body's).
Mesh file names become absolute, so the written files may live anywhere.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from estimator.spatial import inertial as si


def _num(x) -> str:
    return f"{float(x):.12g}"


def urdf_with_parameters(model, theta) -> str:
    """The URDF text of ``model.robot`` (a UrdfModel) with inertial parameters θ (module doc)."""
    import pinocchio as pin

    from estimator.spatial.robot import _resolve_mesh

    robot = model.robot
    urdf_path = Path(robot.urdf_path)
    root = ET.fromstring(urdf_path.read_text(), parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    links = {l.get("name"): l for l in root.findall("link")}
    body_of = {}
    for fr in robot.model.frames:
        if fr.type == pin.FrameType.BODY and fr.parentJoint >= 1:
            body_of[fr.name] = fr.parentJoint - 1
    m, h, Io = si.unpack(theta)
    for name, link in links.items():
        for old in link.findall("inertial"):
            link.remove(old)
        b = body_of.get(name)
        if b is None or model.tree.body_names[b] != name:
            continue                                  # a link fixed to another: merged there
        c = h[b] / m[b]
        Ic = Io[b] - m[b] * si._S(c)
        el = ET.Element("inertial")
        ET.SubElement(el, "origin", xyz=" ".join(_num(x) for x in c), rpy="0 0 0")
        ET.SubElement(el, "mass", value=_num(m[b]))
        ET.SubElement(el, "inertia", ixx=_num(Ic[0, 0]), ixy=_num(Ic[0, 1]), ixz=_num(Ic[0, 2]),
                      iyy=_num(Ic[1, 1]), iyz=_num(Ic[1, 2]), izz=_num(Ic[2, 2]))
        el.tail = "\n    "
        link.insert(0, el)
    for mesh in root.iter("mesh"):
        mesh.set("filename", _resolve_mesh(mesh.get("filename", ""), urdf_path, str(urdf_path)))
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def declaration_toml(declaration: dict, urdf_name: str, name: str, decl_dir: Path,
                     identification: dict | None = None, header: str = "") -> str:
    """A declaration TOML: the original's fields (``declaration``, read from ``decl_dir``) naming
    ``urdf_name``, without its [model_uncertainty], with an [identification] table."""
    from estimator.inertial import toml_lines

    data = {k: v for k, v in declaration.items() if k not in ("model_uncertainty", "identification")}
    data["name"], data["urdf"] = name, urdf_name
    for c in data.get("collision", []):
        if isinstance(c, dict) and "mesh" in c:
            c["mesh"] = str((decl_dir / c["mesh"]).resolve())
    L = [header.rstrip()] if header else []
    L += toml_lines(data)
    if identification:                       # the layout of estimator.inertial.robot_toml
        L += ["", "[identification]"] + toml_lines(identification, "identification")
    return "\n".join(L).rstrip() + "\n"
