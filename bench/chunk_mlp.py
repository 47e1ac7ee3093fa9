"""A small MLP regressor in numpy (ReLU hidden layers, a linear output, mean squared error,
Adam), for the behaviour-cloned chunk policy of `oricf.bench.train_chunk_policy`.

Seeded end to end: the same data, sizes and seed give the same weights. The layers are
kept as (weights [in, out], bias [out]) pairs, the layout `oricf.models.mlp_source.to_onnx`
writes as MatMul/Add/Relu.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass

import numpy as np

log = logging.getLogger(__name__)

Layers = list[tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Fit:
    """How to train: passes over the data, minibatch size, Adam's step size."""

    epochs: int
    batch: int = 256
    lr: float = 1e-3


def init_layers(sizes: list[int], rng: np.random.Generator) -> Layers:
    """He-initialised weights and zero biases for sizes[0] -> ... -> sizes[-1]."""
    return [(rng.normal(0.0, np.sqrt(2.0 / n_in), (n_in, n_out)).astype(np.float32),
             np.zeros(n_out, np.float32))
            for n_in, n_out in itertools.pairwise(sizes)]


def forward(layers: Layers, x: np.ndarray) -> list[np.ndarray]:
    """Each layer's output, the input first (ReLU after all but the last)."""
    outputs = [x]
    for i, (w, b) in enumerate(layers):
        y = outputs[-1] @ w + b
        outputs.append(np.maximum(y, 0.0) if i < len(layers) - 1 else y)
    return outputs


def gradients(layers: Layers, x: np.ndarray, target: np.ndarray
              ) -> tuple[float, list[tuple[np.ndarray, np.ndarray]]]:
    """The mean squared error on this batch and its gradient for every weight and bias."""
    outputs = forward(layers, x)
    error = outputs[-1] - target
    loss = float(np.mean(error ** 2))
    delta = 2.0 * error / error.size
    grads: list[tuple[np.ndarray, np.ndarray]] = []
    for i in range(len(layers) - 1, -1, -1):
        grads.append((outputs[i].T @ delta, delta.sum(axis=0)))
        if i:
            delta = (delta @ layers[i][0].T) * (outputs[i] > 0)
    return loss, grads[::-1]


class Adam:
    def __init__(self, layers: Layers, lr: float) -> None:
        self.lr, self.t = lr, 0
        self.m = [np.zeros_like(p) for layer in layers for p in layer]
        self.v = [np.zeros_like(p) for layer in layers for p in layer]

    def update(self, layers: Layers, grads: list[tuple[np.ndarray, np.ndarray]],
               beta1: float = 0.9, beta2: float = 0.999, eps: float = 1e-8) -> None:
        self.t += 1
        params = [p for layer in layers for p in layer]
        flat = [g for pair in grads for g in pair]
        scale = self.lr * np.sqrt(1 - beta2 ** self.t) / (1 - beta1 ** self.t)
        for p, g, m, v in zip(params, flat, self.m, self.v, strict=True):
            m *= beta1
            m += (1 - beta1) * g
            v *= beta2
            v += (1 - beta2) * g * g
            p -= scale * m / (np.sqrt(v) + eps)  # in place: the layers' own arrays


def train(x: np.ndarray, y: np.ndarray, hidden: list[int], fit: Fit, seed: int) -> Layers:
    """An MLP x -> hidden... -> y fitted by minibatch Adam, in float32."""
    rng = np.random.default_rng(seed)
    layers = init_layers([x.shape[1], *hidden, y.shape[1]], rng)
    return fit_layers(layers, x, y, fit, rng)


def fit_layers(layers: Layers, x: np.ndarray, y: np.ndarray, fit: Fit,
               rng: np.random.Generator) -> Layers:
    """`layers` fitted further to x -> y by minibatch Adam (in place), in float32."""
    x, y = x.astype(np.float32), y.astype(np.float32)
    adam = Adam(layers, fit.lr)
    for epoch in range(fit.epochs):
        order = rng.permutation(len(x))
        losses = []
        for start in range(0, len(x), fit.batch):
            rows = order[start:start + fit.batch]
            loss, grads = gradients(layers, x[rows], y[rows])
            adam.update(layers, grads)
            losses.append(loss)
        if epoch % 10 == 0 or epoch == fit.epochs - 1:
            log.info("epoch %d/%d: loss %.5f", epoch + 1, fit.epochs, float(np.mean(losses)))
    return layers
