"""ROS 2 interoperability: the rmw_zenoh wire format, conversions between ROS messages and
acslam's, bags."""
