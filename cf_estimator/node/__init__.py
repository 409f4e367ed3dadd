"""The rclpy adapter (``cf_estimator_node``). Importing this package does not import rclpy:
only :mod:`cf_estimator.node.cf_estimator_node` does."""
