"""ORICF: AI models as gRPC services, wired to ROS 2 topics by YAML."""

__version__ = "0.1.0"
