"""ROS 2 bags: a recording out as a rosbag2 bag (MCAP storage), and a robot's bag read back as a
joint log (rosbags, the pure-Python rosbag2 library)."""
