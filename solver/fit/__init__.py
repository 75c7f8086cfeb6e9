"""Fitting a model to data: the damped least-squares (Levenberg–Marquardt) core that every fit and the rig
learner's joints-and-poses step use (:mod:`.least_squares`), pose initialisation, per-frame pose fits, and
the evaluation metrics of a fit (surface error, joint-centre error, RMSE).
"""
