"""The Open Inference Protocol (KServe v2) gRPC contract: generated stubs, never edited."""
