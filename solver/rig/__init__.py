"""The character model and what it computes: skeleton, rest mesh, anchors and swing/twist skin
(``model``), forward kinematics, the hybrid skin, its analytic Jacobians, and the linear-blend conversion.
"""
