"""vplayground_ros: a real-time rigid-body sandbox for ROS 2 and Foxglove."""
