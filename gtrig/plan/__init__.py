"""Planning an installation: the ground truth's predicted coverage and covariance over the floor.

For a planned rig (nominal camera and scanner poses, intrinsics, the robot's markers and hull) and a
floor area or a path, :func:`gtrig.plan.predict.predict_plan` says per floor cell and heading which
cameras see which markers, which scanners see which hull sides, and the pose covariance GTvision,
GTlaser and their fusion would report there, with the noise models and Jacobians of those estimators.
"""
