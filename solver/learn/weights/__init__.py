"""Twist and swing weights by sampling-based block coordinate descent (dissertation (model-adaptive mocap)
§3.4 (A), anchors §1.5): each vertex has an anchor part and twist/swing weights on the anchor's children;
blocks of vertices more than two rings apart take their best candidate weights with exactly additive gains.

Modules, bottom up:
* :mod:`.qp`: the swing QP, exact minimiser of a small convex quadratic on ``{0 ≤ w ≤ 1, Σ w ≤ 1}``;
* :mod:`.candidates`: a vertex's twist-weight candidates (slide, fork, backward, forward by a step δ);
* :mod:`.skin`: posed positions of candidates per candidate anchor (the hybrid skin, affine in swing);
* :mod:`.state`: posed vertices, Laplacian residuals, each vertex's completed square; the active set;
* :mod:`.evaluation`: each vertex's best candidate (screened by normal equations, exact recheck);
* :mod:`.colouring`: two-ring colour classes (the blocks) and the cut into halves;
* :mod:`.sweeps`: the joint move, the visit of the classes, halves in parallel, step pruning;
* :mod:`.optimise`: :func:`optimise_weights`, the entry point learn_rig calls.

Design notes and measurements: docs/learn_rig_solver.md, "Weight step: design notes and measurements"."""
