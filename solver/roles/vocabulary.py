"""The bone roles of a humanoid: the one vocabulary retargeting, the pose priors, the start poses, learned
rigs' bone names and gaze share.

A role names one bone of a humanoid by what it does, not by what a rig calls it: ``upper_arm.L`` is the
bone whose head sits at the left shoulder joint and that reaches towards the elbow.  Roles form a tree
(:data:`PARENT`); every role but the ends has a *primary child* (:data:`NEXT`), and the role's *segment*
runs from its joint to the joint of the first primary child both rigs have (e.g. ``hips`` → ``spine``,
``forearm.L`` → ``hand.L``).  Retargeting makes each segment point where the source's points.

Left/right follow the character (``.L`` = the character's left), as in Blender's naming convention.
Which bone of a rig plays which role: :mod:`.recognise`.
"""
SIDES = ("L", "R")
FINGERS = ("thumb", "index", "middle", "ring", "pinky")

CENTRE = ("hips", "spine", "chest", "neck", "head")
ARM = ("shoulder", "upper_arm", "forearm", "hand")
LEG = ("hip", "thigh", "shin", "foot", "toe")


def _sided(base: str, side: str) -> str:
    return f"{base}.{side}"


def _finger_roles(side: str) -> list:
    return [_sided(f"{finger}.{k:02d}", side) for finger in FINGERS for k in (1, 2, 3)]


def _chain(seq, top, parent, nxt):
    """Link the roles ``seq`` as a chain hanging from role ``top``."""
    parent[seq[0]] = top
    for a, b in zip(seq, seq[1:]):
        parent[b], nxt[a] = a, [b]


def _build():
    roles, parent, nxt = list(CENTRE), {"hips": None}, {}
    for i, (a, b) in enumerate(zip(CENTRE, CENTRE[1:])):
        parent[b], nxt[a] = a, list(CENTRE[i + 1:])
    for side in SIDES:
        arm, leg = [_sided(r, side) for r in ARM], [_sided(r, side) for r in LEG]
        roles += arm + leg + _finger_roles(side)
        _chain(arm, "chest", parent, nxt)
        _chain(leg, "hips", parent, nxt)
        nxt[arm[-1]] = [_sided(f"{f}.01", side) for f in ("middle", "index", "ring", "pinky")]
        for finger in FINGERS:
            _chain([_sided(f"{finger}.{k:02d}", side) for k in (1, 2, 3)], arm[-1], parent, nxt)
    return tuple(roles), parent, nxt


ROLES, PARENT, NEXT = _build()
CORE = ("hips", "spine", "chest", "neck", "head",
        *[_sided(r, s) for s in SIDES for r in ("upper_arm", "forearm", "hand", "thigh", "shin", "foot")])
LEG_ROLES = {s: (_sided("thigh", s), _sided("shin", s), _sided("foot", s)) for s in SIDES}


def side(role: str) -> str:
    """``'L'``, ``'R'`` or ``''`` of a role name."""
    return role[-1] if role[-2:] in (".L", ".R") else ""


def mirror(role: str) -> str:
    """The role on the other side (``upper_arm.L`` ↔ ``upper_arm.R``); centre roles are their own mirror."""
    s = side(role)
    return role if not s else role[:-1] + ("R" if s == "L" else "L")


def is_finger(role: str) -> bool:
    return role.split(".", 1)[0] in FINGERS


def ordered(roles) -> list:
    """``roles`` in :data:`ROLES` order (parents before children)."""
    wanted = set(roles)
    return [r for r in ROLES if r in wanted]
