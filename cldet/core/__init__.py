"""The estimator core: pure algorithms on numpy arrays (no I/O, no file paths).

Modules follow the algorithm's steps: ``frames`` (pair the two LiDARs, filter points),
``background`` (static range image over time bins), ``clustering`` (exact DBSCAN of the
foreground), ``tracking`` (candidate constant-velocity Kalman tracks), ``selection`` (the
drone's chain of tracks from whole-sequence evidence), ``smoothing`` (Kalman/RTS,
extrapolation), ``bias`` (centroid correction and its fit) and ``estimator`` (composes them
behind one interface; ``cldet_baseline`` is the CL-Det method).
"""
