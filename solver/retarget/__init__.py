"""Retargeting captured motion onto other characters (bone roles, mapping, per-segment directions,
root motion).  Empty until the retargeting issue lands.
"""
