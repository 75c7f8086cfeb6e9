"""Tracking a model through unregistered scans and depth recordings (per-frame articulated
registration, priors, temporal windows, model adaptation).  Empty until the tracking issues land.
"""
