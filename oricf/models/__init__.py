"""Declared models: the YAML schema, back ends, pre- and post-processing, the model loaded
from a declaration (`declared`), what a model is (`info`), tensors on the wire."""
