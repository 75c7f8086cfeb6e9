"""Fitting a model to data: pose initialisation, per-frame pose fits by Levenberg-Marquardt, and the
evaluation metrics of a fit (surface error, joint-centre error, RMSE).
"""
