"""The estimator core: pure algorithms on numpy arrays (no I/O, no file paths).

Modules follow the algorithm's steps: ``frames`` (pair the two LiDARs), ``background`` (static
occupancy), ``clustering`` (exact DBSCAN of the foreground), ``tracking`` (candidate tracks and
their whole-sequence selection), ``smoothing`` (RTS), ``bias`` (centroid correction) and
``estimator`` (composes them behind one interface; ``cldet_baseline`` is the CL-Det method).
"""
