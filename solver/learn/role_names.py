"""Human role names (the vocabulary :mod:`solver.roles`) for the bones of a learned humanoid skeleton.

A learned rest pose is one of the scans (any pose of a range of motion), the root part may be the chest
or the pelvis and the scans' up axis is unknown, so recognition uses what no pose changes: the tree and
the distances between the joints of each rigid part.  ``hips`` is a part with two long branches (legs)
and ``chest`` a part with two long branches (arms) and a shorter one (neck and head), the two joined by
the spine (or one part); the longest such configuration wins.  Up is the direction from the hips to the
neck; a humanoid has at least one leg hanging along −up (a quadruped's legs hang across its spine).
Along a limb, knee and elbow, ankle and wrist are the joints nearest the human proportions of the limb's
length; a first bone much shorter than the limb is the girdle (``hip``/``shoulder``).  The character's
left is ``up × forward`` of each leg, forward being where the foot points from the shin (the foot bone,
else the farthest rest vertex of the leg's end from its axis).
"""
import numpy as np

from ..roles import ARM, LEG

LEG_JOINTS = ((0.42, 0.25, 0.62), (0.80, 0.66, 0.95))   # knee, ankle: (target, lo, hi) fractions of the leg
ARM_JOINTS = ((0.42, 0.25, 0.62), (0.75, 0.62, 0.92))   # elbow, wrist, from the shoulder joint
GIRDLE = 0.2            # a first limb bone shorter than this fraction of the limb is hip / shoulder
PAIR_RATIO = 0.6        # the shorter limb of a pair is at least this fraction of the longer
EXTRA = 0.5            # any other branch at the hips or chest is shorter than this fraction of a limb
LEG_DOWN = 0.35         # some leg's hip-to-end direction has at least this component along -up
FOOT_BAND = 0.2         # the leg's end region: the last fraction of its reach along the shin
REQUIRED = ("hips", "head", "thigh.L", "shin.L", "thigh.R", "shin.R", "upper_arm.L", "forearm.L",
            "upper_arm.R", "forearm.R")


class _Tree:
    """The skeleton as an undirected tree of rigid parts, with pose-invariant branch lengths."""

    def __init__(self, skeleton):
        self.sk = skeleton
        B = skeleton.num_bones
        self.nbrs = [[] for _ in range(B)]
        for b in range(1, B):
            p = int(skeleton.parents[b])
            self.nbrs[b].append(p)
            self.nbrs[p].append(b)
        self.children = [skeleton.children(b) for b in range(B)]

    def joint(self, a, b):
        """The joint between neighbouring parts a and b (metres)."""
        return self.sk.heads[b] if self.sk.parents[b] == a else self.sk.heads[a]

    def end(self, x):
        """Where a branch ends in part x: its tail for a bone without children, else its head (root)."""
        return self.sk.tails[x] if not self.children[x] else self.sk.heads[x]

    def branch(self, m, n):
        """``(length, path)`` of the longest way from the joint of parts m, n into n's side: path = parts
        from n to the far end part; length along the joints, metres."""
        best = (0.0, [n])
        stack = [(n, m, self.joint(m, n), 0.0, [n])]
        while stack:
            x, prev, entry, s, path = stack.pop()
            ahead = [y for y in self.nbrs[x] if y != prev]
            if not ahead:
                total = s + float(np.linalg.norm(self.end(x) - entry))
                best = max(best, (total, path), key=lambda t: t[0])
            for y in ahead:
                j = self.joint(x, y)
                stack.append((y, x, j, s + float(np.linalg.norm(j - entry)), path + [y]))
        return best

    def between(self, a, b):
        """Parts strictly between a and b on the tree path (from a's side), and a's neighbour towards b."""
        up_a, up_b = self._up(a), self._up(b)
        common = next(x for x in up_a if x in set(up_b))
        path = up_a[:up_a.index(common) + 1] + up_b[:up_b.index(common)][::-1]
        return path[1:-1], path[1]

    def _up(self, b):
        out = [b]
        while self.sk.parents[out[-1]] >= 0:
            out.append(int(self.sk.parents[out[-1]]))
        return out


def recognise(skeleton, rest_vertices=None, anchor=None):
    """``({role: bone index}, why)``: the roles of a humanoid ``skeleton`` (:class:`solver.rig.model.Skeleton`),
    or ``({}, why not)``.  ``rest_vertices (V,3)`` and ``anchor (V,)`` (optional) tell forward from the
    feet when the skeleton has no foot bones."""
    tree = _Tree(skeleton)
    best = _best_layout(tree)
    if best is None:
        return {}, "no hips with two legs and chest with two arms and a head"
    roles, why = _limbs(tree, best)
    if roles is None:
        return {}, why
    side = _left_leg(tree, best, roles, rest_vertices, anchor)
    if side is None:
        return {}, "left and right cannot be told apart (no foot direction)"
    return _sided(tree, best, roles, side), "humanoid"


def role_names(skeleton, rest_vertices=None, anchor=None):
    """New bone names for ``skeleton``: role names for the recognised bones, the old names for the others
    (a ``.L``/``.R`` suffix swapped where the learned pairs' sides are the character's other side);
    None when the skeleton is not recognised as a humanoid (:func:`recognise`)."""
    roles, _ = recognise(skeleton, rest_vertices, anchor)
    return names_for(skeleton, roles) if roles else None


def names_for(skeleton, roles):
    """Bone names from ``{role: bone index}``; unrecognised ``.L``/``.R`` bones follow the recognised ones'
    sides (all swapped when most recognised sided bones had the other suffix)."""
    names = list(skeleton.names)
    votes = [(names[b][-2:] in (".L", ".R")) and (names[b][-1] != r[-1])
             for r, b in roles.items() if r[-2:] in (".L", ".R") and names[b][-2:] in (".L", ".R")]
    if votes and sum(votes) * 2 > len(votes):
        swap = {"L": "R", "R": "L"}
        names = [n[:-1] + swap[n[-1]] if n[-2:] in (".L", ".R") else n for n in names]
    for role, b in roles.items():
        names[b] = role
    return names


def _best_layout(tree):
    """``dict(P, C, legs, arms, head)`` of the longest valid layout (each limb ``(length, path)``), or None."""
    forks = [b for b in range(len(tree.nbrs)) if len(tree.nbrs[b]) >= 3]
    best, best_score = None, 0.0
    for P in forks:
        for C in forks:
            layout = _layout(tree, P, C)
            if layout is not None and _valid(tree, layout):
                score = sum(t[0] for t in layout["legs"] + layout["arms"])
                if score > best_score:
                    best, best_score = layout, score
    return best


def _layout(tree, P, C):
    """Legs at P, arms and head at C (the longest branches off the spine), or None."""
    if P == C:
        ways = sorted((tree.branch(P, n) for n in tree.nbrs[P]), key=lambda t: -t[0])
        if len(ways) < 5:
            return None
        if len(ways) > 5 and ways[5][0] > EXTRA * ways[3][0]:
            return None
        head, limbs = ways[4], ways[:4]
        hj = tree.joint(P, head[1][0])
        dist = [float(np.linalg.norm(tree.joint(P, t[1][0]) - hj)) for t in limbs]
        order = np.argsort(dist)
        return dict(P=P, C=C, arms=[limbs[i] for i in order[:2]], legs=[limbs[i] for i in order[2:]], head=head)
    _, toward_c = tree.between(P, C)
    _, toward_p = tree.between(C, P)
    legs = sorted((tree.branch(P, n) for n in tree.nbrs[P] if n != toward_c), key=lambda t: -t[0])
    tops = sorted((tree.branch(C, n) for n in tree.nbrs[C] if n != toward_p), key=lambda t: -t[0])
    if len(legs) < 2 or len(tops) < 3:
        return None
    if (len(legs) > 2 and legs[2][0] > EXTRA * legs[1][0]) or (len(tops) > 3 and tops[3][0] > EXTRA * tops[1][0]):
        return None                         # a third leg-long branch at the hips (a tail), or at the chest
    return dict(P=P, C=C, legs=legs[:2], arms=tops[:2], head=tops[2])


def _valid(tree, layout):
    """Limb pairs of similar length, a head shorter than the arms, and a leg hanging along −up."""
    (l1, _), (l2, _) = layout["legs"]
    (a1, _), (a2, _) = layout["arms"]
    if min(l1, l2) < PAIR_RATIO * max(l1, l2) or min(a1, a2) < PAIR_RATIO * max(a1, a2):
        return False
    if layout["head"][0] >= max(a1, a2) or min(l1, l2, a1, a2) <= 0:
        return False
    up = _up(tree, layout)
    if up is None:
        return False
    P = layout["P"]
    down = []
    for length, path in layout["legs"]:
        hip = tree.joint(P, path[0])
        d = tree.end(path[-1]) - hip
        down.append(-float(d @ up) / max(float(np.linalg.norm(d)), 1e-12))
    return max(down) >= LEG_DOWN


def _up(tree, layout):
    """Unit vector from the middle of the hip joints to the neck joint, or None."""
    P, C = layout["P"], layout["C"]
    hips = np.mean([tree.joint(P, t[1][0]) for t in layout["legs"]], axis=0)
    d = tree.joint(C, layout["head"][1][0]) - hips
    n = float(np.linalg.norm(d))
    return d / n if n > 1e-9 else None


def _chain(tree, top, length, path, joints):
    """``[girdle bone or None, bone per limb joint ...]`` along ``path`` (parts from ``top``); None when the
    middle joint (knee/elbow) is missing.  ``joints``: (target, lo, hi) fractions of the limb's length."""
    points = [tree.joint(top, path[0])] + [tree.joint(a, b) for a, b in zip(path, path[1:])]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    start = 0
    if len(path) >= 3 and s[1] < GIRDLE * length:
        start = 1
    out = [path[0] if start else None, path[start]]
    total, base, at = length - s[start], s[start], start
    for target, lo, hi in joints:
        cand = [i for i in range(at + 1, len(path)) if lo <= (s[i] - base) / total <= hi]
        if not cand:
            break
        at = min(cand, key=lambda i: abs((s[i] - base) / total - target))
        out.append(path[at])
    if len(out) < 3:
        return None
    if len(out) == 4 and at + 1 < len(path):
        out.append(path[at + 1])            # the bone after the ankle / wrist: toe (legs)
    return out


def _limbs(tree, layout):
    """``({role without side: bone}, why)``: torso and head roles, and ``legs``/``arms`` bone lists."""
    P, C = layout["P"], layout["C"]
    roles = {"hips": P}
    if C != P:
        roles["chest"] = C
        spine, _ = tree.between(P, C)
        if spine:
            roles["spine"] = spine[0]
    head_path = layout["head"][1]
    roles.update({"neck": head_path[0], "head": head_path[1]} if len(head_path) > 1 else {"head": head_path[0]})
    legs = [_chain(tree, P, *t, LEG_JOINTS) for t in layout["legs"]]
    arms = [_chain(tree, C, *t, ARM_JOINTS) for t in layout["arms"]]
    if any(x is None for x in legs):
        return None, "a leg has no knee"
    if any(x is None for x in arms):
        return None, "an arm has no elbow"
    roles["legs"], roles["arms"] = legs, arms
    return roles, ""


def _left_leg(tree, layout, roles, rest_vertices, anchor):
    """Index (0/1) of the character's left leg in ``layout["legs"]``, or None."""
    lateral = tree.sk.heads[roles["legs"][0][1]] - tree.sk.heads[roles["legs"][1][1]]   # thigh to thigh
    vote = 0.0
    for leg, t in zip(roles["legs"], layout["legs"]):
        shin = leg[2]
        axis = tree.sk.frames[shin][:, 1]
        forward = _foot_forward(tree, leg, t[1], axis, rest_vertices, anchor)
        if forward is None:
            continue
        left = np.cross(-axis, forward)
        vote += float(left @ lateral)
    if abs(vote) < 1e-3 * float(np.linalg.norm(lateral)):
        return None
    return 0 if vote > 0 else 1


def _foot_forward(tree, leg, path, axis, rest_vertices, anchor):
    """Unit vector ⊥ the shin ``axis`` along which the foot points, or None."""
    sk = tree.sk
    if len(leg) > 3:
        d = sk.tails[leg[3]] - sk.heads[leg[3]]
    elif rest_vertices is not None and anchor is not None:
        knee = sk.heads[leg[2]]
        pts = rest_vertices[np.isin(anchor, path[path.index(leg[2]):])] - knee
        if len(pts) < 10:
            return None
        along = pts @ axis
        lo, hi = along.min(), along.max()
        shank = pts[(along >= lo + 0.5 * (hi - lo)) & (along <= lo + 0.7 * (hi - lo))]
        if len(shank) < 3 or np.linalg.norm(shank.mean(axis=0)) < 1e-9:
            return None
        axis = shank.mean(axis=0) / np.linalg.norm(shank.mean(axis=0))     # knee to the lower shank
        along = pts @ axis
        foot = pts[along >= along.max() - FOOT_BAND * (along.max() - along.min())]
        d = foot.mean(axis=0)
    else:
        return None
    d = d - (d @ axis) * axis
    n = float(np.linalg.norm(d))
    return d / n if n > 1e-9 else None


def _sided(tree, layout, roles, left_leg):
    """``{role: bone}`` with ``.L``/``.R``: legs by ``left_leg``, arms on the side of the hip nearer them."""
    out = {k: v for k, v in roles.items() if k not in ("legs", "arms")}
    heads = tree.sk.heads
    left = heads[roles["legs"][left_leg][1]] - heads[roles["legs"][1 - left_leg][1]]
    shoulders = [heads[arm[1]] for arm in roles["arms"]]
    left_arm = 0 if float((shoulders[0] - shoulders[1]) @ left) > 0 else 1
    for names, limbs, first in ((LEG, roles["legs"], left_leg), (ARM, roles["arms"], left_arm)):
        for i, bones in enumerate(limbs):
            side = "L" if i == first else "R"
            out.update({f"{name}.{side}": b for name, b in zip(names, bones) if b is not None})
    return out


def name_bones(model, info):
    """Give ``model``'s skeleton role names in place when it is a humanoid (:func:`recognise` with its
    rest mesh and anchors), renaming the pairs in ``info["mirror_pairs"]`` too.  Returns the report
    entry ``{"scheme": "roles" | "parts", "roles": count, "why": ...}``."""
    sk = model.skeleton
    roles, why = recognise(sk, model.rest_vertices, model.anchor)
    if not roles:
        return dict(scheme="parts", roles=0, why=f"not recognised as a humanoid: {why}")
    new = dict(zip(sk.names, names_for(sk, roles)))
    sk.names = [new[n] for n in sk.names]
    if info.get("mirror_pairs"):
        info["mirror_pairs"] = [tuple(new.get(n, n) for n in pair) for pair in info["mirror_pairs"]]
    return dict(scheme="roles", roles=len(roles), why=why)
