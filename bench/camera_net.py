"""A chunk policy that sees, in numpy: a camera image and a state vector in, a chunk of
actions out, for `oricf.bench.train_camera_policy`.

The image goes through a spatial soft-argmax (the "keypoints" of Levine et al.'s
visuomotor policies): each of `keypoints` learned colour filters (a 1x1 convolution over
the RGB planes) scores every pixel, a softmax over the pixels makes the scores a
distribution, and its expected position (x and y in [-1, 1]) is that keypoint. The
keypoints, concatenated after the normalised state, feed an MLP (oricf.bench.chunk_mlp)
that answers the chunk. Where the target is in the image is then two numbers a few dozen
weights find, instead of a pixel-wise regression that a few hundred demonstrations cannot
cover; a blank image gives every keypoint the image's centre.

Trained end to end (mean squared error, Adam, seeded), and written as ONNX: Conv, Reshape,
Softmax, MatMul, Concat, then the MLP's MatMul/Add/Relu.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from oricf.bench.chunk_mlp import Adam, Fit, Layers, fit_layers, forward, init_layers
from oricf.models.mlp_source import dense_layers, model_bytes

log = logging.getLogger(__name__)

FILTER_LR = 10.0  # the filters' step size, in the MLP's


@dataclass
class Net:
    filters: np.ndarray        # [keypoints, 3]: each keypoint's colour filter
    layers: Layers             # the MLP: [state + 2 x keypoints] -> ... -> chunk x dim

    @property
    def keypoints(self) -> int:
        return int(self.filters.shape[0])


def grid(height: int, width: int) -> np.ndarray:
    """[pixels, 2]: each pixel's centre as (x, y) in [-1, 1], x to the right, y up."""
    xs = (np.arange(width) + 0.5) / width * 2 - 1
    ys = 1 - (np.arange(height) + 0.5) / height * 2
    x, y = np.meshgrid(xs, ys)
    return np.stack([x.reshape(-1), y.reshape(-1)], axis=1).astype(np.float32)


def softmax(scores: np.ndarray) -> np.ndarray:
    shifted = np.exp(scores - scores.max(axis=-1, keepdims=True))
    return shifted / shifted.sum(axis=-1, keepdims=True)


def keypoints(filters: np.ndarray, images: np.ndarray, coords: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """images [n, 3, pixels] -> (keypoints [n, k, 2], the softmax [n, k, pixels])."""
    weights = softmax(np.einsum("kc,ncp->nkp", filters, images))
    return weights @ coords, weights


def act(net: Net, states: np.ndarray, images: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """[n, chunk x dim] for normalised states [n, s] and images [n, 3, pixels]."""
    points, _ = keypoints(net.filters, images, coords)
    features = np.hstack([states, points.reshape(len(states), -1)])
    return forward(net.layers, features.astype(np.float32))[-1]


def gradients(net: Net, states: np.ndarray, images: np.ndarray, target: np.ndarray,
              coords: np.ndarray) -> tuple[float, list[tuple[np.ndarray, np.ndarray]]]:
    """The batch's mean squared error and its gradient for the filters (paired with a zero
    for Adam's layout) and every MLP layer."""
    points, weights = keypoints(net.filters, images, coords)
    outputs = forward(net.layers, np.hstack([states, points.reshape(len(states), -1)]))
    error = outputs[-1] - target
    delta = 2.0 * error / error.size
    grads: list[tuple[np.ndarray, np.ndarray]] = []
    for i in range(len(net.layers) - 1, -1, -1):
        grads.append((outputs[i].T @ delta, delta.sum(axis=0)))
        delta = delta @ net.layers[i][0].T
        if i:
            delta = delta * (outputs[i] > 0)
    to_points = delta[:, states.shape[1]:].reshape(points.shape)      # [n, k, 2]
    to_weights = to_points @ coords.T                                  # [n, k, pixels]
    to_scores = weights * (to_weights - (weights * to_weights).sum(-1, keepdims=True))
    to_filters = np.einsum("nkp,ncp->kc", to_scores, images)
    grads.append((to_filters, np.zeros(net.keypoints, np.float32)))
    return float(np.mean(error ** 2)), grads[::-1]


def train(states: np.ndarray, images: np.ndarray, targets: np.ndarray, hidden: list[int],
          count: int, fit: Fit, seed: int, size: tuple[int, int], joint_epochs: int) -> Net:
    """The net fitted by minibatch Adam: states [n, s] normalised, images [n, 3, h x w] as
    the model gets them, targets [n, chunk x dim]; size is (width, height). The filters
    and the MLP are fitted together for `joint_epochs` of the `fit.epochs`; then, the
    filters kept, each image's keypoints are found once and the MLP alone is fitted on
    them for the rest: the same gradient steps at a small part of the cost."""
    rng = np.random.default_rng(seed)
    states, images = states.astype(np.float32), images.astype(np.float32)
    targets = targets.astype(np.float32)
    net = Net(rng.normal(0.0, 1.0, (count, 3)).astype(np.float32),
              init_layers([states.shape[1] + 2 * count, *hidden, targets.shape[1]], rng))
    coords = grid(size[1], size[0])
    bias = np.zeros(count, np.float32)  # the softmax ignores a shift: never used
    # The filters' step is larger: a few dozen weights that must grow to a sharp softmax
    # (scores some ten apart) within the few joint epochs.
    colours = Adam([(net.filters, bias)], fit.lr * FILTER_LR)
    mlp = Adam(net.layers, fit.lr)
    joint = min(joint_epochs, fit.epochs)
    for epoch in range(joint):
        order, losses = rng.permutation(len(states)), []
        for start in range(0, len(states), fit.batch):
            rows = order[start:start + fit.batch]
            loss, grads = gradients(net, states[rows], images[rows], targets[rows], coords)
            colours.update([(net.filters, bias)], grads[:1])
            mlp.update(net.layers, grads[1:])
            losses.append(loss)
        log.info("epoch %d/%d (keypoints and MLP): loss %.5f", epoch + 1, fit.epochs,
                 float(np.mean(losses)))
    if joint < fit.epochs:
        points = np.concatenate([keypoints(net.filters, images[i:i + fit.batch], coords)[0]
                                 for i in range(0, len(images), fit.batch)])
        fit_layers(net.layers, np.hstack([states, points.reshape(len(states), -1)]), targets,
                   Fit(fit.epochs - joint, fit.batch, fit.lr), rng)
    return net


def to_onnx(net: Net, state_size: int, size: tuple[int, int], name: str) -> bytes:
    """`state` [batch, state_size] and `image` [batch, 3, h, w] -> `action` [batch, chunk x
    dim]: the keypoints (Conv 1x1, Softmax over the pixels, their expected position), then
    the MLP on [state, keypoints]."""
    from onnx import TensorProto, helper, numpy_helper

    width, height = size
    k = net.keypoints
    inits = [numpy_helper.from_array(net.filters.reshape(k, 3, 1, 1).astype(np.float32),
                                     "filters"),
             numpy_helper.from_array(grid(height, width), "coords"),
             numpy_helper.from_array(np.array([0, k, height * width], np.int64), "by_pixel"),
             numpy_helper.from_array(np.array([0, 2 * k], np.int64), "by_item")]
    nodes = [helper.make_node("Conv", ["image", "filters"], ["scores"]),
             helper.make_node("Reshape", ["scores", "by_pixel"], ["flat"]),
             helper.make_node("Softmax", ["flat"], ["weights"], axis=-1),
             helper.make_node("MatMul", ["weights", "coords"], ["points"]),
             helper.make_node("Reshape", ["points", "by_item"], ["keypoints"]),
             helper.make_node("Concat", ["state", "keypoints"], ["features"], axis=1)]
    mlp_nodes, mlp_inits = dense_layers(net.layers, "features", "action")
    nodes += mlp_nodes
    inits += mlp_inits
    value = helper.make_tensor_value_info
    graph = helper.make_graph(
        nodes, name,
        [value("state", TensorProto.FLOAT, ["batch", state_size]),
         value("image", TensorProto.FLOAT, ["batch", 3, height, width])],
        [value("action", TensorProto.FLOAT, ["batch", net.layers[-1][0].shape[1]])],
        initializer=inits)
    return model_bytes(graph)
