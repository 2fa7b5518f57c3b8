"""Reading a URDF file's joints: origins and axes as the file writes them (yourdfpy keeps only
the composed matrices), the chain from a base link to a tip link, unique names, checked numbers."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np

from tolsynth.checks import HUGE
from tolsynth.model.fields import _nearest, _Reader, _type_name


# --------------------------------------------------------------------------------------------
# reading the URDF
# --------------------------------------------------------------------------------------------
def _rpy_matrix(xyz, rpy) -> np.ndarray:
    """URDF's origin: Trans(xyz) . Rz(yaw) . Ry(pitch) . Rx(roll) (xyz in any length unit)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    T = np.eye(4)
    T[:3, :3] = (
        np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
        @ np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
        @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    )
    T[:3, 3] = xyz
    return T


def _numbers(text: str, r: _Reader, where: str, what: str, scale: float = 1.0) -> tuple[float, ...]:
    """Three finite numbers of an ``xyz`` / ``rpy`` attribute, each at most HUGE (in mm or rad)
    after ``scale``; a typed error naming the joint otherwise."""
    try:
        v = tuple(float(t) for t in text.split())
    except ValueError:
        v = ()
    if len(v) != 3 or not all(math.isfinite(t) and abs(t * scale) <= HUGE for t in v):
        limit = f"|value| <= {HUGE / scale:g}" + (" m" if scale == 1000.0 else "")
        raise r.fail(where, f"{what}={text!r}: expected three finite numbers, {limit}")
    return v


def _origins(file: str, r: _Reader) -> dict[str, tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]]:
    """Each joint's ``<origin xyz rpy>`` as the file writes them (m, rad) and its ``<axis xyz>``.
    yourdfpy keeps only the composed 4x4 matrix, from which rpy cannot be recovered uniquely at
    pitch = +-90 deg; the error parameters are the file's own numbers, so they are read here (and
    checked against yourdfpy's matrices by the caller).  The tree is checked here too: a link or
    joint declared twice, a link with two parent joints (a closed loop) and a cycle are errors
    naming them (a URDF describes a tree; tolsynth reads a serial chain of it)."""
    root = ET.parse(file).getroot()
    links = [link.get("name") for link in root.findall("link")]
    joints = root.findall("joint")  # not <transmission><joint>
    _unique_names(r, links, "link")
    _unique_names(r, [j.get("name") for j in joints], "joint")
    parent_of: dict[str, str] = {}
    for joint in joints:
        child, parent = joint.find("child"), joint.find("parent")
        child = child.get("link") if child is not None else None
        if child in parent_of:
            raise r.fail(
                f"joint {joint.get('name')!r}",
                f"link {child!r} is also the child of joint {parent_of[child]!r}: "
                "a closed loop (not supported: a URDF chain must be a tree)",
            )
        parent_of[child] = joint.get("name")
        parent_link = parent.get("link") if parent is not None else None
        parent_of.setdefault(f"link:{child}", parent_link)
    for link in links:  # a cycle: following the parents never reaches a root
        seen, at = set(), link
        while at is not None:
            if at in seen:
                raise r.fail(
                    f"link {link!r}", "its parent joints form a cycle (not supported: a URDF chain must be a tree)"
                )
            seen.add(at)
            at = parent_of.get(f"link:{at}")
    out = {}
    for joint in joints:
        name = joint.get("name")
        origin = joint.find("origin")
        xyz = _numbers(
            origin.get("xyz", "0 0 0") if origin is not None else "0 0 0", r, f"joint {name!r}", "origin xyz", 1000.0
        )
        rpy = _numbers(
            origin.get("rpy", "0 0 0") if origin is not None else "0 0 0", r, f"joint {name!r}", "origin rpy"
        )
        axis_el = joint.find("axis")
        axis = _numbers(
            axis_el.get("xyz", "1 0 0") if axis_el is not None else "1 0 0", r, f"joint {name!r}", "axis xyz"
        )
        out[name] = (xyz, rpy, axis)
    return out


def _unique_names(r: _Reader, names: list, what: str) -> None:
    seen = set()
    for n in names:
        if n is None or not str(n).strip():
            raise r.fail(f"{what} {n!r}", f"a {what} without a name")
        if n in seen:
            raise r.fail(f"{what} {n!r}", f"declared twice (each {what} name once)")
        seen.add(n)


def _chain(robot, base: str, tip: str, r: _Reader, where: str) -> list:
    """The URDF joints from ``base`` to ``tip``, base first."""
    links = [link.name for link in robot.links]
    for key, link in (("base_link", base), ("tip_link", tip)):
        if not isinstance(link, str):
            raise r.fail(f"{where}.{key}", f"expected a link name, got {_type_name(link)}: {link!r:.60}")
        if link not in links:
            raise r.fail(f"{where}.{key}", f"no link {link!r} in the URDF{_nearest(link, links)}")
    by_child = {j.child: j for j in robot.joints}
    path = []
    link = tip
    while link != base:
        joint = by_child.get(link)
        if joint is None:
            raise r.fail(f"{where}.tip_link", f"link {tip!r} does not descend from base_link {base!r}")
        path.append(joint)
        link = joint.parent
    if not path:
        raise r.fail(f"{where}.tip_link", "is the base link itself: the chain is empty")
    return path[::-1]


def _axis_angles(axis: np.ndarray) -> tuple[float, float]:
    """(phi, theta) with Rz(phi) . Ry(theta) . z = axis (unit)."""
    return math.atan2(axis[1], axis[0]), math.acos(max(-1.0, min(1.0, axis[2])))
