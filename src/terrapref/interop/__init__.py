"""terrapref and the robot's world: ROS bags in, ONNX models and MCAP runs out, label maps."""
