"""Declared models served over the Open Inference Protocol (`oricf serve models`)."""
