"""Tests run against the real models, real gRPC servers on localhost and real DDS.

Nothing is skipped for a missing model or tool: run scripts/setup.sh --dev first.
"""
