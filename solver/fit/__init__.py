"""Fitting a model to data: the damped least-squares (Levenberg–Marquardt) core that every fit and the rig
learner's joints-and-poses step use (:mod:`.least_squares`), pose initialisation and per-frame pose fits.
(The evaluation metrics of learned rigs are the benchmarks': bench/_learn_metrics.py.)
"""
