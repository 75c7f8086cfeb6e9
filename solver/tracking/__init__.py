"""One tracking core that the scan tracker (:mod:`solver.track`) and the depth tracker
(:mod:`solver.track_depth`) stand on: the body evaluated exactly with Jacobians on the vertices a fit
needs, residual terms, priors, one robust Levenberg–Marquardt, start poses and truth-free checks
(docs/track.md "Design")."""
