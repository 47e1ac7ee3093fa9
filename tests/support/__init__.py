"""Shared test helpers: real services on port 0, real data from the model store."""
