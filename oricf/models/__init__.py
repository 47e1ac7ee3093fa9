"""Declared models: the YAML schema, back ends, pre- and post-processing, tensors on the wire."""
