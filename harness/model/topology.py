"""Graph-theoretic description of a mechanism (Arczewski 1995).

The *system graph* G of a mechanism has vertex 0 for the reference body (ground, the world frame)
and vertices 1..n for the bodies in declaration order; its edges are the joints in declaration
order, each oriented from its ``body1`` to its ``body2``.

Sign conventions (Arczewski 1995 defers the definitions of S and P to Wittenburg 1977, its ref. [1])
-----------------------------------------------------------------------------------------------
* Incidence matrix Ŝ = [S0; S], shape (n + 1, n_joints): Ŝ[i, e] = +1 when edge e leaves vertex i
  (vertex i is the edge's ``body1``), −1 when it enters vertex i (its ``body2``), 0 otherwise.
  Its split Ŝ = Ŝ₊ − Ŝ₋ (seed eq. 2) then has Ŝ₋ marking the vertex each edge enters.
* Path matrix P of a spanning tree, shape (n_tree_joints, n): P[e, b] = +1 when tree edge e lies
  on the path from ground to body b and points along that path (away from ground), −1 when it
  points against it (towards ground), 0 otherwise.  This is the sign for which the seed's eq. 3,
  Ω = ω0·1 + Pᵀω, holds with ω_e the rate of the edge's head (``body2``) relative to its tail
  (``body1``), the direction in which the seed's measurement arcs point.  It equals −T of
  Wittenburg, whose path matrix is signed towards ground; with S_T the columns of S that belong to
  tree edges, P·S_T = −I and S0_T·P = 1ᵀ.

With a fixed ground (ω0 = 0) and joint axes expressed in world coordinates, eq. 3 generalises to
space as Ω_b = Σ_e P[e, b] ω_e a_e: the absolute angular velocity of a body is the signed sum of
the axis rates of the rotating joints on its path (:func:`angular_velocities`).

Cut joints are chosen by enumerating every spanning tree (:func:`spanning_tree`) while there are
at most :data:`EXHAUSTIVE_LIMIT` candidate cuts (the shipped scenes have a handful of joints: the
search is cheap and its choice exact); larger graphs (the N-four-bar from N = 8 on has C(3N+1, N)
candidates) get Kruskal's maximum-cost spanning tree with the same preferences
(:func:`_greedy_cut`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from mbh._harness.common.errors import MbhError
from mbh._harness.model.mechanism import (GROUND, PLANAR_JOINT_CLASS, SPATIAL_JOINT_CLASS, Joint,
                                          Mechanism)

#: Largest number of candidate cut sets :func:`spanning_tree` enumerates (about 1 s of search).
EXHAUSTIVE_LIMIT = 20_000
#: Joint types that let body2 turn relative to body1 about the joint axis by one angle.
ROTATING_JOINTS = ("revolute", "cylindrical")
#: Joint types that allow no relative rotation; they add nothing to the angular velocities.
SLIDING_JOINTS = ("prismatic", "translational")


@dataclass(frozen=True, eq=False)
class SystemGraph:
    """The system graph G of a mechanism (Arczewski 1995, §2).

    Compared by identity (``eq=False``): the incidence array makes field-wise equality ambiguous.

    Attributes
    ----------
    vertices : tuple of str, length n_bodies + 1
        ``"ground"`` followed by the body names in declaration order.
    edges : tuple of str, length n_joints
        Joint names in declaration order.
    incidence : ndarray, shape (n_bodies + 1, n_joints)
        Ŝ = [S0; S]: +1 where an edge leaves a vertex, −1 where it enters (read-only).
    """

    vertices: tuple[str, ...]
    edges: tuple[str, ...]
    incidence: np.ndarray


@dataclass(frozen=True, eq=False)
class SpanningTree:
    """A spanning tree of the system graph and the joints cut to obtain it.

    Attributes
    ----------
    bodies : tuple of str
        Body names in declaration order: the columns of :meth:`path_matrix`.
    tree_joints, cut_joints : tuple of str
        Joint names in declaration order; together they are all the joints.
    parent : dict
        Body name → its parent body, or ``"ground"``.
    parent_joint : dict
        Body name → the tree joint connecting it to its parent.
    order : tuple of str
        Bodies with every parent before its children (by depth, then declaration order).
    flipped : dict
        Tree joint name → True when the tree runs from its ``body2`` to its ``body1``.
    redundant_closure_equations : int
        Closure equations on the cut joints beyond the number the joints impose (see
        :func:`spanning_tree`).
    """

    bodies: tuple[str, ...]
    tree_joints: tuple[str, ...]
    cut_joints: tuple[str, ...]
    parent: dict[str, str]
    parent_joint: dict[str, str]
    order: tuple[str, ...]
    flipped: dict[str, bool]
    redundant_closure_equations: int

    def depth_first_order(self) -> tuple[str, ...]:
        """Bodies in depth-first pre-order from ground, siblings in name order.

        Every subtree is one contiguous run of this sequence, the numbering that recursive
        multibody algorithms index their subtrees by (Featherstone's λ(i) < i with contiguous
        subtrees, as Pinocchio's ``nvSubtree`` and Bullet's link re-sorting assume).

        Returns
        -------
        tuple of str
            Body names, each parent before its children and each subtree contiguous; the same
            sequence whatever the order in which the scenario declares its bodies.
        """
        children: dict[str, list[str]] = {GROUND: []}
        for body in sorted(self.bodies):
            children.setdefault(body, [])
            children.setdefault(self.parent[body], []).append(body)
        ordered: list[str] = []
        pending = [GROUND]
        while pending:
            vertex = pending.pop()
            if vertex != GROUND:
                ordered.append(vertex)
            pending.extend(reversed(children[vertex]))
        return tuple(ordered)

    def path_matrix(self) -> np.ndarray:
        """The path matrix P, signed as in the module docstring.

        Returns
        -------
        ndarray, shape (n_tree_joints, n_bodies)
            Rows follow :attr:`tree_joints`, columns :attr:`bodies`.
        """
        row = {name: index for index, name in enumerate(self.tree_joints)}
        paths = np.zeros((len(self.tree_joints), len(self.bodies)))
        for column, body in enumerate(self.bodies):
            vertex = body
            while vertex != GROUND:
                joint = self.parent_joint[vertex]
                paths[row[joint], column] = -1.0 if self.flipped[joint] else 1.0
                vertex = self.parent[vertex]
        return paths


def _vertex_row(mech: Mechanism, name: str) -> int:
    """Row of vertex ``name`` in Ŝ: 0 for ground, 1 + declaration index for a body."""
    return mech.body_index(name) + 1


def incidence_matrix(mech: Mechanism) -> np.ndarray:
    """The incidence matrix Ŝ = [S0; S] of the system graph (Arczewski 1995, §2).

    Parameters
    ----------
    mech : Mechanism

    Returns
    -------
    ndarray, shape (n_bodies + 1, n_joints)
        Ŝ[i, e] = +1 when joint e's ``body1`` is vertex i, −1 when its ``body2`` is; row 0 is
        ground, row 1 + k the k-th declared body; columns follow the declared joints.
    """
    incidence = np.zeros((len(mech.bodies) + 1, len(mech.joints)))
    for column, joint in enumerate(mech.joints):
        incidence[_vertex_row(mech, joint.body1), column] = 1.0
        incidence[_vertex_row(mech, joint.body2), column] = -1.0
    return incidence


def system_graph(mech: Mechanism) -> SystemGraph:
    """The system graph G of ``mech``: vertices, edges and incidence matrix.

    Parameters
    ----------
    mech : Mechanism

    Returns
    -------
    SystemGraph
    """
    incidence = incidence_matrix(mech)
    incidence.setflags(write=False)
    return SystemGraph(vertices=(GROUND, *(body.name for body in mech.bodies)),
                       edges=tuple(joint.name for joint in mech.joints),
                       incidence=incidence)


def _reachable_tree(joints: tuple[Joint, ...]) -> dict[str, Joint]:
    """Breadth-first search from ground over ``joints``.

    Returns
    -------
    dict
        Every body reachable from ground → the joint through which the search first reached it,
        in the order reached.
    """
    reached: dict[str, Joint] = {}
    frontier = [GROUND]
    while frontier:
        following = []
        for vertex in frontier:
            for joint in joints:
                other = _other_end(joint, vertex)
                if other is not None and other != GROUND and other not in reached:
                    reached[other] = joint
                    following.append(other)
        frontier = following
    return reached


def _other_end(joint: Joint, vertex: str) -> str | None:
    """The body at the other end of ``joint`` from ``vertex``, or None if ``joint`` misses it."""
    if joint.body1 == vertex:
        return joint.body2
    if joint.body2 == vertex:
        return joint.body1
    return None


class DisconnectedGraphError(MbhError, ValueError):
    """A body of the mechanism has no chain of joints to ground: it has no spanning tree."""


def _require_connected(mech: Mechanism) -> None:
    """Raise :class:`DisconnectedGraphError` naming the bodies of ``mech`` that no joint path
    links to ground."""
    reached = _reachable_tree(mech.joints)
    lost = [body.name for body in mech.bodies if body.name not in reached]
    if lost:
        raise DisconnectedGraphError(f"mechanism {mech.name!r}: the system graph is disconnected; "
                                     f"no chain of joints links {', '.join(map(repr, lost))} "
                                     "to ground")


def _closure_costs(mech: Mechanism, closure_equations: Callable[[Joint], int]) -> list[int]:
    """``closure_equations`` of every joint, checked to be a non-negative integer."""
    costs = []
    for joint in mech.joints:
        cost = closure_equations(joint)
        if isinstance(cost, bool) or not isinstance(cost, (int, np.integer)) or cost < 0:
            raise ValueError(f"closure_equations({joint.name!r}) must be a non-negative integer, "
                             f"got {cost!r}")
        costs.append(int(cost))
    return costs


def _depths(parent: dict[str, str]) -> dict[str, int]:
    """Number of tree edges between each body and ground."""
    depths: dict[str, int] = {}
    for body in parent:
        depth, vertex = 0, body
        while vertex != GROUND:
            depth, vertex = depth + 1, parent[vertex]
        depths[body] = depth
    return depths


def _tree_from(mech: Mechanism, tree: tuple[Joint, ...]) -> dict[str, Joint] | None:
    """Body → parent joint if ``tree`` spans every body of ``mech``, else None."""
    reached = _reachable_tree(tree)
    return reached if len(reached) == len(mech.bodies) else None


def _parents(reached: dict[str, Joint]) -> dict[str, str]:
    """Body → parent vertex, from the joint through which the search reached each body."""
    return {body: _other_end(joint, body) for body, joint in reached.items()}


def spanning_tree(mech: Mechanism, closure_equations: Callable[[Joint], int]) -> SpanningTree:
    """Choose the spanning tree of the system graph with the cheapest cut joints.

    Every spanning tree is a candidate: each set of n_joints − n_bodies joints whose removal
    leaves a tree linking all bodies to ground.  The chosen one minimises, in turn,

    1. the closure cost Σ ``closure_equations(joint)`` over the cut joints,
    2. the largest number of tree joints between a body and ground,
    3. the names of the cut joints, sorted and compared lexicographically,

    so the choice never depends on the order in which the scenario declares its joints.

    Parameters
    ----------
    mech : Mechanism
    closure_equations : callable
        ``closure_equations(joint) -> int``: how many constraint equations the caller (an engine)
        needs to close the loop at ``joint`` when it is cut.

    Returns
    -------
    SpanningTree
        ``redundant_closure_equations`` is Σ max(0, closure_equations(joint) − class) over the
        cut joints, with the class the number of independent equations the joint imposes in the
        mechanism's own dimension (:data:`~mbh._harness.model.mechanism.PLANAR_JOINT_CLASS` for a planar
        mechanism, :data:`~mbh._harness.model.mechanism.SPATIAL_JOINT_CLASS` otherwise).

    Raises
    ------
    ValueError
        If some body is not linked to ground (the message names the mechanism and those bodies),
        or ``closure_equations`` returns something other than a non-negative integer.
    """
    _require_connected(mech)
    costs = _closure_costs(mech, closure_equations)
    n_cut = len(mech.joints) - len(mech.bodies)
    if math.comb(len(mech.joints), n_cut) > EXHAUSTIVE_LIMIT:
        cut = _greedy_cut(mech, costs)
        reached = _tree_from(mech, tuple(j for i, j in enumerate(mech.joints) if i not in cut))
        return _assemble(mech, cut, reached, _parents(reached), costs)
    best_key, best = None, None
    for cut in combinations(range(len(mech.joints)), n_cut):
        reached = _tree_from(mech, tuple(j for i, j in enumerate(mech.joints) if i not in cut))
        if reached is None:
            continue
        parent = _parents(reached)
        key = (sum(costs[i] for i in cut), max(_depths(parent).values(), default=0),
               sorted(mech.joints[i].name for i in cut))
        if best_key is None or key < best_key:
            best_key, best = key, (cut, reached, parent)
    cut, reached, parent = best
    return _assemble(mech, cut, reached, parent, costs)


def _levels(mech: Mechanism) -> dict[str, int]:
    """Graph distance of every vertex from ground over all joints (breadth-first)."""
    levels, frontier = {GROUND: 0}, [GROUND]
    while frontier:
        following = []
        for vertex in frontier:
            for joint in mech.joints:
                other = _other_end(joint, vertex)
                if other is not None and other not in levels:
                    levels[other] = levels[vertex] + 1
                    following.append(other)
        frontier = following
    return levels


def _greedy_cut(mech: Mechanism, costs: list[int]) -> tuple[int, ...]:
    """Cut joints of a maximum-cost spanning tree by Kruskal's method (polynomial, for graphs
    whose spanning trees are too many to enumerate).

    Joints enter the tree most expensive first (so the cut ones are the cheapest: criterion 1 of
    :func:`spanning_tree` exactly), then those linking consecutive breadth-first levels from
    ground nearest to ground first (with equal costs this builds a breadth-first tree, whose
    depth is the least any spanning tree has: criterion 2), then later names first (so that the
    earlier names are left to be cut: criterion 3).  Verified equal to the
    exhaustive choice on every shipped scene and on n_fourbar@1…6
    (tests/model/test_topology.py) and, once, on n_fourbar@8 (17.5 s of enumeration against 0.2 ms).
    """
    levels = _levels(mech)

    def preference(index: int):
        joint = mech.joints[index]
        ends = (levels[joint.body1], levels[joint.body2])
        return (-costs[index], abs(ends[0] - ends[1]) != 1, max(ends))

    component = {vertex: vertex for vertex in levels}

    def root(vertex: str) -> str:
        while component[vertex] != vertex:
            component[vertex] = component[component[vertex]]
            vertex = component[vertex]
        return vertex

    by_name = sorted(range(len(mech.joints)), key=lambda i: mech.joints[i].name, reverse=True)
    cut = []
    for index in sorted(by_name, key=preference):  # stable: later names first among equals
        joint = mech.joints[index]
        a, b = root(joint.body1), root(joint.body2)
        if a == b:
            cut.append(index)
        else:
            component[a] = b
    return tuple(sorted(cut))


def _assemble(mech: Mechanism, cut: tuple[int, ...], reached: dict[str, Joint],
              parent: dict[str, str], costs: list[int]) -> SpanningTree:
    """Build the :class:`SpanningTree` for the chosen set of cut joint indices."""
    names = [body.name for body in mech.bodies]
    depths = _depths(parent)
    joint_class = PLANAR_JOINT_CLASS if mech.planar else SPATIAL_JOINT_CLASS
    redundant = sum(max(0, costs[i] - joint_class[mech.joints[i].type]) for i in cut)
    tree_joints = tuple(j.name for i, j in enumerate(mech.joints) if i not in cut)
    flipped = {joint.name: joint.body2 == parent[body] for body, joint in reached.items()}
    return SpanningTree(
        bodies=tuple(names),
        tree_joints=tree_joints,
        cut_joints=tuple(mech.joints[i].name for i in cut),
        parent={body: parent[body] for body in names},
        parent_joint={body: reached[body].name for body in names},
        order=tuple(sorted(names, key=lambda body: (depths[body], names.index(body)))),
        flipped={name: flipped[name] for name in tree_joints},
        redundant_closure_equations=redundant,
    )


def _check_tree(mech: Mechanism, tree: SpanningTree) -> None:
    """Raise a ValueError unless ``tree`` spans ``mech``'s bodies with rotating/sliding joints."""
    names = tuple(body.name for body in mech.bodies)
    if tree.bodies != names:
        raise ValueError(f"tree: its bodies {tree.bodies} are not those of mechanism "
                         f"{mech.name!r} {names}")
    for name in tree.tree_joints:
        kind = mech.joint(name).type
        if kind not in ROTATING_JOINTS + SLIDING_JOINTS:
            raise ValueError(f"tree: joint {name!r} of mechanism {mech.name!r} is {kind}; the "
                             f"angular-velocity map takes only {ROTATING_JOINTS + SLIDING_JOINTS}")


def _as_rows(name: str, value, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as a float array of ``shape``, else a ValueError naming the argument."""
    array = np.asarray(value, dtype=float)
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
    return array


def angular_velocities(mech: Mechanism, tree: SpanningTree, joint_axes_world,
                       joint_rates) -> np.ndarray:
    """Absolute angular velocities from joint rates, ground fixed (Arczewski 1995, eq. 3, ω0 = 0).

    Ω_b = Σ_e P[e, b] ω_e a_e over the rotating tree joints e, with P the tree's path matrix.

    Parameters
    ----------
    mech : Mechanism
    tree : SpanningTree
        A spanning tree of ``mech`` whose joints are revolute, cylindrical, prismatic or
        translational.
    joint_axes_world : array_like, shape (n_tree_joints, 3)
        Unit axis of each tree joint (order of ``tree.tree_joints``) in world coordinates at the
        current configuration.  Rows of prismatic and translational joints are not used.
    joint_rates : array_like, shape (n_tree_joints,)
        Angular rate (rad/s) of each joint's ``body2`` relative to its ``body1`` about the axis,
        right-hand rule.  Entries of prismatic and translational joints are not used.

    Returns
    -------
    ndarray, shape (n_bodies, 3)
        Absolute angular velocity of each body (declaration order), world frame, rad/s.

    Raises
    ------
    ValueError
        If ``tree`` does not belong to ``mech``, holds a joint with more than one rotation
        (spherical, universal), or an array has the wrong shape.
    """
    _check_tree(mech, tree)
    n_tree = len(tree.tree_joints)
    axes = _as_rows("joint_axes_world", joint_axes_world, (n_tree, 3))
    rates = _as_rows("joint_rates", joint_rates, (n_tree,))
    turning = np.array([mech.joint(name).type in ROTATING_JOINTS for name in tree.tree_joints])
    relative = np.where(turning[:, None], rates[:, None] * axes, 0.0)
    return tree.path_matrix().T @ relative
