"""A dynamics network's weights as NumPy arrays, and its forward pass: applying a model without torch.

Importing torch costs a command more than a second on a workstation, more than the network
itself takes on a thousand frames of a face. So a model read from a file keeps its network
as these arrays (named as the torch module's state_dict), `remove`, `synthesize` and a
linear response run the forward pass here on the CPU, and the torch module is built from
them (facedyn.dynamics.network.Network.from_weights, taking the arrays over without a copy)
only where something trains the network or runs it on a GPU (facedyn.dynamics.inference
says where a model runs).

The forward pass is the torch module's, in float32: inputs standardized per feature, ReLU
between the layers, outputs scaled back by one common scale and a per-coordinate mean. It
takes BLOCK_ROWS rows through all the layers at a time: a thousand frames of F's samples
are 344,000 rows, whose hidden layer (176 MB) would otherwise go out to memory and back at
every step; blocked, F's forward pass on them takes a quarter less time (0.215 -> 0.163 s on
two cores).
"""
from __future__ import annotations

import numpy as np

from facedyn.dynamics.netspec import NetworkSpec

BLOCK_ROWS = 4096  # rows taken through every layer together: their hidden layers stay in the CPU's cache


class NetworkWeights:
    """An MLP's weights and normalization (float32 arrays) and its forward pass."""

    def __init__(self, spec: NetworkSpec, state: dict[str, np.ndarray]):
        expected = _state_shapes(spec)
        missing, unknown = sorted(set(expected) - set(state)), sorted(set(state) - set(expected))
        if missing or unknown:
            raise ValueError(f"the {spec} network's weights are missing {missing} and hold unexpected {unknown}")
        for name, shape in expected.items():
            if np.shape(state[name]) != shape:
                raise ValueError(f"the network's {name} is {np.shape(state[name])}, its architecture needs {shape}")
        self.spec = spec
        self.state = {name: np.asarray(state[name], dtype=np.float32) for name in expected}

    @classmethod
    def of(cls, network) -> "NetworkWeights":
        """The weights of a network: these weights, or a torch Network's (sharing its CPU memory)."""
        if isinstance(network, cls):
            return network
        return cls(network.spec, {name: value.detach().cpu().numpy() for name, value in network.state_dict().items()})

    @classmethod
    def normalized(cls, spec: NetworkSpec, layers: list[tuple[np.ndarray, np.ndarray]], input_mean, input_std, output_mean,
                   output_scale: float) -> "NetworkWeights":
        """Weights from (weight (out, in), bias) per layer and the statistics (`normalization_state`)."""
        state = normalization_state(input_mean, input_std, output_mean, output_scale)
        state.update({f"layers.{2 * i}.weight": w for i, (w, _) in enumerate(layers)})
        state.update({f"layers.{2 * i}.bias": b for i, (_, b) in enumerate(layers)})
        return cls(spec, state)

    def layers(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(weight (out, in), bias (out,)) of each linear layer, first to last."""
        count = len(self.spec.hidden) + 1
        return [(self.state[f"layers.{2 * i}.weight"], self.state[f"layers.{2 * i}.bias"]) for i in range(count)]

    def forward(self, inputs: np.ndarray) -> np.ndarray:
        """(rows, outputs) float32 for (rows, inputs) raw features."""
        x = np.asarray(inputs, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != self.spec.inputs:
            raise ValueError(f"the network takes (rows, {self.spec.inputs}) inputs, got {x.shape}")
        return self.forward_split(np.empty((len(x), 0), np.float32), x[:, None, :])[:, 0]  # no shared part: the same products

    def forward_split(self, shared: np.ndarray, items: np.ndarray) -> np.ndarray:
        """(F, I, outputs) float32: forward(concat(shared[f], items[f, i])) for all f, i, without the concatenation.

        shared: (F, Ds) inputs common to every item of a frame (F's skull features B(t));
        items: (F, I, Di) per-item inputs. The first layer's shared part is computed once
        per frame, with the normalization folded into the weights (Network.forward_split).
        """
        shared = np.asarray(shared, dtype=np.float32)
        items = np.asarray(items, dtype=np.float32)
        ds = shared.shape[-1]
        if ds + items.shape[-1] != self.spec.inputs:
            raise ValueError(f"inputs of sizes {ds} + {items.shape[-1]} do not add up to the network's {self.spec.inputs}")
        (weight, bias), *rest = self.layers()
        rest = _transposed(rest)
        scaled = weight / self.state["input_std"]
        per_frame = shared @ scaled[:, :ds].T
        per_frame += bias - scaled @ self.state["input_mean"]
        first = np.ascontiguousarray(scaled[:, ds:].T)
        frames, count = items.shape[:2]
        out = np.empty((frames, count, self.spec.outputs), np.float32)
        step = max(1, BLOCK_ROWS // max(count, 1))  # whole frames per block
        for a in range(0, frames, step):
            block = items[a:a + step]
            h = block.reshape(-1, block.shape[-1]) @ first
            h.reshape(len(block), count, -1)[:] += per_frame[a:a + step, None, :]
            out[a:a + step] = self._rest(h, rest).reshape(len(block), count, -1)
        return self._scaled_back(out)

    @staticmethod
    def _rest(h: np.ndarray, rest: list) -> np.ndarray:
        """A block's layers after the first (ReLU before each), in place where it can; rest: (weight.T, bias)."""
        for weight_t, bias in rest:
            np.maximum(h, 0.0, out=h)
            h = h @ weight_t
            h += bias
        return h

    def _scaled_back(self, out: np.ndarray) -> np.ndarray:
        """The outputs in their units: times the common scale, plus the per-coordinate mean (in place)."""
        out *= self.state["output_scale"]
        out += self.state["output_mean"]
        return out


def _transposed(layers: list) -> list:
    """(weight.T as a contiguous array, bias) of each layer: the layout a block's product reads fastest."""
    return [(np.ascontiguousarray(weight.T), bias) for weight, bias in layers]


def normalization_state(input_mean, input_std, output_mean, output_scale: float) -> dict[str, np.ndarray]:
    """A network's standardization statistics as float32 arrays, by name; a zero spread becomes 1,
    so a constant input passes as 0 (the torch module's set_normalization keeps the same)."""
    std = np.asarray(input_std, dtype=np.float64)
    scale = float(output_scale) if output_scale > 1e-12 else 1.0
    return {"input_mean": np.asarray(input_mean, np.float32), "input_std": np.where(std > 1e-12, std, 1.0).astype(np.float32),
            "output_mean": np.asarray(output_mean, np.float32), "output_scale": np.array([scale], np.float32)}


def _state_shapes(spec: NetworkSpec) -> dict[str, tuple[int, ...]]:
    """The arrays a network of this shape holds, by name, and their shapes, in the torch module's
    state_dict order (its own statistics, then the layers): the order a model file stores them in."""
    sizes = (spec.inputs, *spec.hidden, spec.outputs)
    shapes: dict[str, tuple[int, ...]] = {"input_mean": (spec.inputs,), "input_std": (spec.inputs,), "output_mean": (spec.outputs,),
                                          "output_scale": (1,)}
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        shapes[f"layers.{2 * i}.weight"] = (b, a)
        shapes[f"layers.{2 * i}.bias"] = (b,)
    return shapes
