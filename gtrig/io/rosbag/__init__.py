"""ROS 1 and ROS 2 bags (sqlite3 or MCAP) in and out, with the ``rosbags`` library.

- :mod:`gtrig.io.rosbag.trajectory`: trajectories from pose, odometry, path and TF topics; a pose
  track written as PoseWithCovarianceStamped, a nav_msgs/Path and TF.
- :mod:`gtrig.io.rosbag.covariance`: gtrig's covariances as ROS's 6 x 6 and back.
- :mod:`gtrig.io.rosbag.topics`: what a bag holds, and a topics.yaml to start an import from.
- :mod:`gtrig.io.rosbag.record_import`: a bag into the recording layout (docs/formats.md).
- :mod:`gtrig.io.rosbag.record_export`: a recording into a bag (images, scans, odometry).
"""

from gtrig.io.rosbag.trajectory import read_bag_trajectory, write_bag_trajectory

__all__ = ["read_bag_trajectory", "write_bag_trajectory"]
