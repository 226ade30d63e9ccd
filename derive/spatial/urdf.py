"""URDF import (build time only): a base -> tip serial chain as a :class:`derive.spatial.chain.ChainDescription`.

Parsed with the standard library's XML parser (:mod:`xml.parsers.expat`, the
parser behind :mod:`xml.etree`, maintained with CPython), which reports line
numbers; the URDF elements used here (``link``, ``joint``, ``origin``,
``axis``, ``parent``, ``child``, ``inertial``, ``mass``, ``inertia``,
``mimic``) are then checked against the URDF specification by this module.
Nothing is evaluated: numbers are read with :func:`float` from
whitespace-separated attribute tokens. Visual, collision, dynamics and any
other elements are ignored (they do not enter the dynamics). A moving joint's
``<limit>`` (``effort``, ``velocity``, ``lower``, ``upper``) does not enter the
dynamics either; it is read as data (:attr:`UrdfChain.limits`, recorded in the
manifest for the consumers of the model), as the URDF states it: no
placeholder is replaced, a missing ``<limit>`` or attribute is None.

Rules (each violation raises :class:`UrdfError` naming the file, the line,
the element and what was expected):

* ``base`` and ``tip`` must be links, the tip a descendant of the base (or
  several tips, each a descendant: the union of their paths is a tree); every
  link has at most one parent joint (a second one closes a loop) and the
  joint graph has no cycle;
* joints on the base -> tip path are ``revolute``, ``continuous`` (both:
  one generalized coordinate) or ``fixed`` (merged into the
  parent body); ``prismatic``, ``planar`` and ``floating`` joints and
  ``<mimic>`` joints on the path are refused;
* the child link of every revolute joint on the path needs an ``<inertial>``
  with mass > 0 and a positive definite inertia tensor;
* links fixed to moving links (through fixed joints, on or off the path) may
  omit ``<inertial>`` -- a massless frame, as URDF allows (``tool0``,
  ``panda_link8``), as does mass 0 with an all-zero tensor; a mass > 0 with
  an all-zero tensor is a point mass; otherwise the same mass and tensor
  checks apply;
* a branch leaving a moving link through a non-fixed joint (off the path,
  or beyond the tip) is refused if any of its links carries mass (the
  chain's dynamics would be wrong without it); massless branches are
  ignored and listed in :attr:`UrdfChain.ignored`;
* links that hang on the base (or on links fixed to it) without moving with
  the chain are ignored: the base is fixed, they do not couple with the
  chain (listed in :attr:`UrdfChain.ignored` too);
* a ``<limit>`` on a moving joint of the chain, if present: its attributes
  are finite numbers, ``effort`` and ``velocity`` >= 0 and ``lower`` <=
  ``upper`` (each attribute optional: fjm does not require ``<limit>``).
"""

from __future__ import annotations

import hashlib
import math
import xml.parsers.expat
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from .chain import Attached, ChainDescription, Inertial, Joint

__all__ = ["UrdfError", "UrdfChain", "JointLimit", "parse_urdf", "load_urdf"]

_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")


class UrdfError(ValueError):
    """A URDF that cannot be used. ``str(err)`` reads ``<file>:<line>: <element>: <problem>``."""

    def __init__(self, message: str, source: str, line: Optional[int] = None, element: str = None):
        self.source, self.line, self.element = source, line, element
        where = source if line is None else f"{source}:{line}"
        super().__init__(f"{where}: {element}: {message}" if element else f"{where}: {message}")


@dataclass
class _Node:
    tag: str
    attrs: Dict[str, str]
    line: int
    children: List["_Node"]

    def find(self, tag: str) -> Optional["_Node"]:
        return next((c for c in self.children if c.tag == tag), None)

    def findall(self, tag: str) -> List["_Node"]:
        return [c for c in self.children if c.tag == tag]

    def label(self) -> str:
        name = self.attrs.get("name")
        return f"<{self.tag} name=\"{name}\">" if name is not None else f"<{self.tag}>"


def _parse_xml(text: Union[str, bytes], source: str) -> _Node:
    parser = xml.parsers.expat.ParserCreate()
    stack: List[_Node] = []
    root: List[_Node] = []

    def start(tag, attrs):
        node = _Node(tag, dict(attrs), parser.CurrentLineNumber, [])
        (stack[-1].children if stack else root).append(node)
        stack.append(node)

    def end(tag):
        stack.pop()

    def no_entities(*args):  # no DTD entities: nothing expands, nothing is fetched
        raise UrdfError("malformed XML: entity declarations are not allowed in a URDF", source,
                        parser.CurrentLineNumber)

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.EntityDeclHandler = no_entities
    try:
        parser.Parse(text, True)
    except xml.parsers.expat.ExpatError as exc:
        raise UrdfError(f"malformed XML: {xml.parsers.expat.ErrorString(exc.code)} "
                        f"(column {exc.offset + 1}); expected a well-formed URDF document",
                        source, exc.lineno) from None
    if not root or root[0].tag != "robot":
        raise UrdfError(f"the root element is <{root[0].tag if root else ''}>; expected <robot>",
                        source, root[0].line if root else None)
    return root[0]


@dataclass(frozen=True)
class JointLimit:
    """A joint's ``<limit>`` as the URDF states it (None: attribute or element absent).

    Attributes
    ----------
    effort : float or None
        N m (the joint torque the URDF allows, link side).
    velocity : float or None
        rad/s.
    lower, upper : float or None
        rad (a ``continuous`` joint has none).
    """

    effort: Optional[float] = None
    velocity: Optional[float] = None
    lower: Optional[float] = None
    upper: Optional[float] = None


@dataclass(frozen=True)
class UrdfChain:
    """Result of :func:`parse_urdf`.

    Attributes
    ----------
    description : ChainDescription
    robot : str
        The ``<robot name>``.
    joints : tuple of str
        Revolute joint names in q order.
    ignored : tuple of str
        Links left out (massless moving branches, links that do not move with the chain).
    sha256 : str
        Of the URDF bytes.
    limits : tuple of JointLimit
        The ``<limit>`` of each revolute joint, in q order (same length as ``joints``).
    """

    description: ChainDescription
    robot: str
    joints: Tuple[str, ...]
    ignored: Tuple[str, ...]
    sha256: str
    limits: Tuple[JointLimit, ...] = ()


class _Reader:
    def __init__(self, source: str):
        self.source = source

    def fail(self, node: _Node, message: str) -> UrdfError:
        return UrdfError(message, self.source, node.line, node.label())

    def floats(self, node: _Node, attr: str, count: int, default=None, owner: _Node = None) -> Tuple[float, ...]:
        raw = node.attrs.get(attr)
        where = f"{(owner or node).label()} {node.label() if owner else ''}".strip()
        if raw is None:
            if default is not None:
                return default
            raise UrdfError(f"missing attribute {attr}; expected {count} number(s)", self.source,
                            node.line, where)
        tokens = raw.split()
        try:
            values = tuple(float(t) for t in tokens)
        except ValueError:
            values = ()
        if len(values) != count or not all(math.isfinite(v) for v in values):
            raise UrdfError(f"{attr}=\"{raw}\"; expected {count} finite number(s) separated by spaces",
                            self.source, node.line, where)
        return values

    def origin(self, owner: _Node) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]:
        o = owner.find("origin")
        if o is None:
            return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        return (self.floats(o, "xyz", 3, (0.0, 0.0, 0.0), owner),
                self.floats(o, "rpy", 3, (0.0, 0.0, 0.0), owner))

    def inertial(self, link: _Node, required: bool) -> Optional[Inertial]:
        node = link.find("inertial")
        if node is None:
            if required:
                raise self.fail(link, "no <inertial>: the child link of a revolute joint on the chain "
                                      "needs <inertial> with <mass> > 0 and a positive definite <inertia>")
            return None
        mass_node, inertia_node = node.find("mass"), node.find("inertia")
        if mass_node is None:
            raise self.fail(link, "<inertial> without <mass value=...>; expected the link mass in kg")
        (mass,) = self.floats(mass_node, "value", 1, owner=link)
        if inertia_node is None:
            raise self.fail(link, "<inertial> without <inertia ixx=... izz=...>; expected the inertia "
                                  "tensor about the centre of mass in kg m^2")
        tensor = tuple(self.floats(inertia_node, k, 1, owner=link)[0]
                       for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))
        xyz, rpy = self.origin(node)
        if mass < 0 or (mass == 0 and required):
            raise UrdfError(f"mass {mass!r} kg; expected > 0", self.source, mass_node.line,
                            f"{link.label()} <mass>")
        if mass == 0:
            if any(v != 0 for v in tensor):
                raise UrdfError("mass 0 with a non-zero inertia tensor; expected mass > 0, or an all-zero "
                                "tensor for a massless frame", self.source, inertia_node.line,
                                f"{link.label()} <inertia>")
            return None
        ixx, ixy, ixz, iyy, iyz, izz = tensor
        eig = np.linalg.eigvalsh(np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]))
        point_mass = not required and all(v == 0 for v in tensor)  # a fixed link's point mass (Baxter's endpoints)
        if not eig.min() > 0 and not point_mass:
            raise UrdfError(f"inertia tensor is not positive definite (eigenvalues "
                            f"{', '.join(f'{v:.3g}' for v in eig)}); expected a symmetric positive "
                            "definite tensor about the centre of mass", self.source, inertia_node.line,
                            f"{link.label()} <inertia>")
        return Inertial(mass=mass, xyz=xyz, rpy=rpy, inertia=tensor)


    def limit(self, joint: _Node) -> JointLimit:
        """The ``<limit>`` of a moving joint (fields None where the URDF states nothing)."""
        node = joint.find("limit")
        if node is None:
            return JointLimit()
        values = {k: self.floats(node, k, 1, default=(None,), owner=joint)[0]
                  for k in ("effort", "velocity", "lower", "upper")}
        for key in ("effort", "velocity"):
            if values[key] is not None and values[key] < 0:
                raise UrdfError(f"{key}=\"{node.attrs[key]}\"; expected a number >= 0", self.source, node.line,
                                f"{joint.label()} <limit>")
        if values["lower"] is not None and values["upper"] is not None and values["lower"] > values["upper"]:
            raise UrdfError(f"lower=\"{node.attrs['lower']}\" > upper=\"{node.attrs['upper']}\"; expected "
                            "lower <= upper", self.source, node.line, f"{joint.label()} <limit>")
        return JointLimit(**values)


Edge = Tuple[_Node, str]  # (joint element, child or parent link name)


def _index_links(robot: _Node, rd: _Reader) -> Dict[str, _Node]:
    """``<link>`` elements by name (each named, no name twice)."""
    links: Dict[str, _Node] = {}
    for node in robot.findall("link"):
        name = node.attrs.get("name")
        if not name:
            raise rd.fail(node, "missing attribute name; expected <link name=\"...\">")
        if name in links:
            raise rd.fail(node, f"link {name!r} defined twice (first at line {links[name].line}); "
                                "expected unique link names")
        links[name] = node
    return links


def _index_joints(robot: _Node, rd: _Reader,
                  links: Dict[str, _Node]) -> Tuple[Dict[str, Edge], Dict[str, List[Edge]]]:
    """The joint tree: child link -> (joint, parent link), and link -> [(joint, child link)]."""
    joints: Dict[str, _Node] = {}
    parent_of: Dict[str, Edge] = {}  # child link -> (joint, parent link)
    children: Dict[str, List[Edge]] = {k: [] for k in links}
    for node in robot.findall("joint"):
        name = node.attrs.get("name")
        if not name:
            raise rd.fail(node, "missing attribute name; expected <joint name=\"...\" type=\"...\">")
        if name in joints:
            raise rd.fail(node, f"joint {name!r} defined twice (first at line {joints[name].line})")
        joints[name] = node
        kind = node.attrs.get("type")
        if kind not in _JOINT_TYPES:
            raise rd.fail(node, f"type={kind!r}; expected one of {', '.join(_JOINT_TYPES)}")
        ends = {}
        for role in ("parent", "child"):
            el = node.find(role)
            if el is None or not el.attrs.get("link"):
                raise rd.fail(node, f"missing <{role} link=\"...\">")
            if el.attrs["link"] not in links:
                raise UrdfError(f"link {el.attrs['link']!r} is not defined; expected the name of a <link>",
                                rd.source, el.line, f"{node.label()} <{role}>")
            ends[role] = el.attrs["link"]
        child = ends["child"]
        if child in parent_of:
            other = parent_of[child][0]
            raise rd.fail(node, f"link {child!r} is already the child of {other.label()} (line {other.line}): "
                                "a closed kinematic loop; expected a tree (each link has at most one parent joint)")
        parent_of[child] = (node, ends["parent"])
        children[ends["parent"]].append((node, child))
    return parent_of, children


def _base_to_tip(robot: _Node, rd: _Reader, links: Dict[str, _Node], parent_of: Dict[str, Edge],
                 base: str, tip: str) -> List[Edge]:
    """The path ``[(joint, child link), ...]`` from the base to the tip."""
    for role, name in (("base", base), ("tip", tip)):
        if name not in links:
            raise UrdfError(f"{role} link {name!r} not found; expected one of the <link> names "
                            f"({', '.join(sorted(links)) or 'none defined'})", rd.source, robot.line,
                            robot.label())
    # Path from the tip up to the base (a cycle would revisit a link).
    path: List[Edge] = []
    seen = {tip}
    link = tip
    while link != base:
        if link not in parent_of:
            raise UrdfError(f"tip link {tip!r} is not a descendant of base link {base!r}; expected a "
                            "base -> tip chain of joints", rd.source, links[tip].line, links[tip].label())
        jnode, parent = parent_of[link]
        if parent in seen:
            raise rd.fail(jnode, f"the joints form a cycle through link {parent!r}; expected a tree")
        seen.add(parent)
        path.append((jnode, link))
        link = parent
    path.reverse()
    return path


def _path_joints(rd: _Reader, links: Dict[str, _Node], path: List[Edge], base: str,
                 tips: Sequence[str], tree: bool = False) -> Tuple[List[Joint], List[str], List[JointLimit]]:
    """The joints on the path or tree (checked), the links that move (beyond a moving joint), and the
    ``<limit>`` of each moving joint in q order.

    ``path`` lists every parent before its children; with ``tree`` the joints name their parent link.
    """
    chain: List[Joint] = []
    moving_links: List[str] = []
    limits: List[JointLimit] = []
    tip = ", ".join(tips)
    for jnode, child in path:
        kind = jnode.attrs["type"]
        parent = jnode.find("parent").attrs["link"]
        moving = parent in moving_links
        if kind in ("prismatic", "planar", "floating"):
            raise rd.fail(jnode, f"type \"{kind}\" on the chain {base} -> {tip}; expected revolute, "
                                 "continuous or fixed (spatial chains of revolute joints only)")
        if kind != "fixed" and jnode.find("mimic") is not None:
            raise rd.fail(jnode, "<mimic> on the chain; expected independent joints (each joint has its "
                                 "own motor and spring)")
        xyz, rpy = rd.origin(jnode)
        axis = (1.0, 0.0, 0.0)
        if kind != "fixed":
            ax = jnode.find("axis")
            if ax is not None:
                axis = rd.floats(ax, "xyz", 3, owner=jnode)
            if not np.linalg.norm(axis) > 0:
                raise rd.fail(jnode, f"<axis xyz=\"{' '.join(map(str, axis))}\"> is zero; expected a non-zero axis")
            limits.append(rd.limit(jnode))
            moving = True
        if moving:
            moving_links.append(child)
        chain.append(Joint(name=jnode.attrs["name"], kind="fixed" if kind == "fixed" else "revolute",
                           xyz=xyz, rpy=rpy, axis=axis, child=child,
                           inertial=rd.inertial(links[child], required=kind != "fixed") if moving else None,
                           parent=parent if tree else None))
    for end in tips:
        if end not in moving_links:
            raise UrdfError(f"no revolute or continuous joint between base {base!r} and tip {end!r}; expected "
                            "at least one", rd.source, links[end].line, links[end].label())
    return chain, moving_links, limits


def _off_path(rd: _Reader, links: Dict[str, _Node], children: Dict[str, List[Edge]], path: List[Edge],
              moving_links: List[str], base: str, tip: str) -> Tuple[List[Attached], List[str]]:
    """Off-path links hanging on moving links: fixed -> attached, non-fixed -> must be massless."""
    on_path = {base} | {c for _, c in path}
    path_joints = {id(j) for j, _ in path}
    attached: List[Attached] = []
    ignored: List[str] = []

    def subtree(link_name: str) -> List[str]:
        out, todo = [], [link_name]
        while todo:
            cur = todo.pop()
            out.append(cur)
            todo.extend(c for _, c in children.get(cur, []))
        return out

    def branch(jnode: _Node, child: str) -> None:
        names = subtree(child)
        massive = [k for k in names if links[k].find("inertial") is not None
                   and (links[k].find("inertial").find("mass") is not None)
                   and rd.floats(links[k].find("inertial").find("mass"), "value", 1, owner=links[k])[0] != 0]
        if massive:
            raise rd.fail(jnode, f"a {jnode.attrs['type']} joint leaves the chain {base} -> {tip} and "
                                 f"carries mass (link(s) {', '.join(sorted(massive))}); expected a serial "
                                 "chain: make the joint fixed, move the tip, or remove the branch")
        ignored.extend(names)

    def attach(owner: str, parent_link: str, origins, todo_link: str) -> None:
        for jnode, child in children.get(todo_link, []):
            if id(jnode) in path_joints:
                continue
            if jnode.attrs["type"] != "fixed":
                branch(jnode, child)
                continue
            o = origins + (rd.origin(jnode),)
            attached.append(Attached(name=child, parent=parent_link, origins=o,
                                     inertial=rd.inertial(links[child], required=False)))
            attach(owner, parent_link, o, child)

    for link_name in moving_links:
        attach(link_name, link_name, (), link_name)
    static = set(subtree(base)) - set(moving_links) - {a.name for a in attached} - set(ignored)
    ignored.extend(k for k in static if k not in on_path)
    return attached, ignored


def _tree_edges(robot: _Node, rd: _Reader, links: Dict[str, _Node], parent_of: Dict[str, Edge], base: str,
                tips: Sequence[str]) -> List[Edge]:
    """The union of the base -> tip paths, depth-first in the order of ``tips`` (shared joints once, first)."""
    if not tips or len(set(tips)) != len(tips) or not all(isinstance(t, str) and t for t in tips):
        raise UrdfError(f"tips {list(tips)!r}; expected distinct link names (at least one)", rd.source,
                        robot.line, robot.label())
    edges: List[Edge] = []
    seen = set()
    for t in tips:
        for jnode, child in _base_to_tip(robot, rd, links, parent_of, base, t):
            if child not in seen:
                seen.add(child)
                edges.append((jnode, child))
    return edges


def parse_urdf(text: Union[str, bytes], base: str, tip: Union[str, Sequence[str]],
               source: str = "<urdf>") -> UrdfChain:
    """Select the serial chain from ``base`` to ``tip`` (or the tree to several tips) of a URDF document.

    Parameters
    ----------
    text : str or bytes
        The URDF document.
    base : str
        Link name.
    tip : str or sequence of str
        The tip link, or several: the tree of the paths from ``base`` to each
        (q order: depth-first in the order the tips are listed, joints shared
        with an earlier path counted once, where they first occur).
    source : str
        File name for messages.

    Returns
    -------
    UrdfChain

    Raises
    ------
    UrdfError
        See the module docstring for the rules.
    """
    data = text.encode() if isinstance(text, str) else bytes(text)
    robot = _parse_xml(data, source)
    rd = _Reader(source)
    links = _index_links(robot, rd)
    parent_of, children = _index_joints(robot, rd, links)
    tips = (tip,) if isinstance(tip, str) else tuple(tip)
    tree = len(tips) > 1
    if tree:
        path = _tree_edges(robot, rd, links, parent_of, base, tips)
    else:
        path = _base_to_tip(robot, rd, links, parent_of, base, tips[0] if tips else "")
    chain, moving_links, limits = _path_joints(rd, links, path, base, tips, tree)
    attached, ignored = _off_path(rd, links, children, path, moving_links, base, ", ".join(tips))
    desc = ChainDescription(base=base, joints=tuple(chain), attached=tuple(attached), tips=tips if tree else ())
    return UrdfChain(description=desc, robot=robot.attrs.get("name", ""), joints=desc.revolute_names,
                     ignored=tuple(sorted(set(ignored))), sha256=hashlib.sha256(data).hexdigest(),
                     limits=tuple(limits))


def load_urdf(path: Union[str, Path], base: str, tip: Union[str, Sequence[str]], source: str = None) -> UrdfChain:
    """Read a URDF file and select the ``base`` -> ``tip`` chain or tree (see :func:`parse_urdf`).

    Raises
    ------
    UrdfError
        For every problem with the content (the message names ``source``, default the path).
    OSError
        If the file cannot be read.
    """
    path = Path(path)
    return parse_urdf(path.read_bytes(), base, tip, source=source or str(path))
