"""Tracking a single depth-camera recording (depth-camera tracking dissertation, ch. 5 and 6; docs/track_depth.md)."""
