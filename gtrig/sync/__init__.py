"""Stage: time sync. Each GT source's clock offset to odometry, and each camera's and fixed scanner's
offset to GTvision's clock, with a 95 % interval and a verdict (ok / ambiguous / unobservable).

Modules, from the bottom up: :mod:`.offset` (a source's offset to odometry from the robot's turns, the
:class:`~gtrig.sync.offset.OffsetEstimate` record), :mod:`.returns` (the fixed scanners' foreground returns),
:mod:`.reference` (the reference trajectory a sensor is timed against, and the shared fit pieces),
:mod:`.cameras` and :mod:`.scanners` (the per-sensor fits), :mod:`.reprojection` (cameras timed by their own
corners), :mod:`.joint_cameras` (cameras refined in the joint fit with GTlaser and odometry) and
:mod:`.sensors` (all of them together, what the pipeline's sync stage calls).
"""
