"""The dynamics networks: fully connected ReLU MLPs that carry their own normalization.

Removal network F (papers/000 §5.2): [B(t), X_i(t)] (315 + 63) -> dx_i(t) (3), two hidden
layers of 128, one network shared by all samples. Synthesis network H (§6) has the same
form, [B(t), S(t)] (315 + 2 per sample) -> dY(t) (3 per sample), two hidden layers of 256,
so both are a `Network` built from a `NetworkSpec` (facedyn.dynamics.netspec), saved and loaded the same way
(facedyn.dynamics.modelfile).

Inputs are standardized per feature and outputs by a per-coordinate mean and one common
scale; the statistics are buffers of the module, so they travel with the weights and a
loaded network takes raw features and returns offsets in centimetres. A single output
scale keeps the training loss proportional to the paper's plain L2 loss on offsets.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from facedyn.dynamics.netspec import NetworkSpec
from facedyn.dynamics.network_weights import NetworkWeights, normalization_state
from facedyn.errors import FacedynError

REMOVAL_HIDDEN = (128, 128)
SYNTHESIS_HIDDEN = (256, 256)


def resolve_device(device: str) -> torch.device:
    """``'auto'`` = the GPU when torch sees one, else the CPU; anything else as torch reads it
    (a CUDA device this torch cannot use is a FacedynError, not torch's assertion)."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    problem = cuda_problem(device) if str(device).startswith("cuda") else None
    if problem:
        raise FacedynError(f"--device {device}: {problem}")
    return torch.device(device)


def cuda_problem(device: str) -> str | None:
    """Why this torch cannot run on the CUDA device `device` ('cuda' or 'cuda:N'), or None."""
    if not torch.cuda.is_available():
        built = "built without CUDA" if torch.version.cuda is None else f"built for CUDA {torch.version.cuda}, but it sees no GPU"
        return f"CUDA is not available in this torch ({torch.__version__}, {built}); use --device cpu or auto"
    index = torch.device(device).index
    if index is not None and index >= torch.cuda.device_count():
        return f"this machine has {torch.cuda.device_count()} CUDA device(s), numbered from 0; there is no {device}"
    return None


def removal_spec(skull_features: int = 315, skin_features: int = 63) -> NetworkSpec:
    return NetworkSpec(skull_features + skin_features, REMOVAL_HIDDEN, 3)


class Network(nn.Module):
    """An MLP on raw features that returns raw (un-normalized) outputs."""

    def __init__(self, spec: NetworkSpec):
        super().__init__()
        self.spec = spec
        sizes = (spec.inputs, *spec.hidden, spec.outputs)
        layers: list[nn.Module] = []
        for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
            layers.append(nn.Linear(a, b))
            if i < len(sizes) - 2:
                layers.append(nn.ReLU())
        self.layers = nn.Sequential(*layers)
        self.register_buffer("input_mean", torch.zeros(spec.inputs))
        self.register_buffer("input_std", torch.ones(spec.inputs))
        self.register_buffer("output_mean", torch.zeros(spec.outputs))
        self.register_buffer("output_scale", torch.ones(1))

    @classmethod
    def from_weights(cls, weights: NetworkWeights) -> "Network":
        """The module holding a model's NumPy weights (no copy, no random initialization: built
        on the meta device, then given the arrays): what training and GPUs use."""
        with torch.device("meta"):
            network = cls(weights.spec)
        network.load_state_dict({name: torch.from_numpy(value) for name, value in weights.state.items()}, assign=True)
        return network.eval()

    def set_normalization(self, input_mean, input_std, output_mean, output_scale) -> None:
        """Standardization statistics (network_weights.normalization_state: zero spreads become 1)."""
        for name, value in normalization_state(input_mean, input_std, output_mean, output_scale).items():
            buf = getattr(self, name)
            buf.copy_(torch.as_tensor(value.reshape(buf.shape)))

    def normalized(self, x: torch.Tensor) -> torch.Tensor:
        """The network's output in normalized units (what the loss compares)."""
        return self.layers((x - self.input_mean) / self.input_std)

    def normalized_split(self, shared: torch.Tensor, items: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        """normalized(concat(shared[rows[k]], items[k])) for every k, as training needs it.

        shared: (U, Ds), items: (B, Di), rows: (B,) indices into shared -> (B, outputs). The
        first layer's shared part is computed once per row of `shared`, not once per item:
        F's skull features are most of its inputs and the same for every skin sample of a
        frame, so a batch whose pairs share frames costs a fraction of the pairs concatenated.
        """
        ds = shared.shape[-1]
        if ds + items.shape[-1] != self.spec.inputs:
            raise ValueError(f"inputs of sizes {ds} + {items.shape[-1]} do not add up to the network's {self.spec.inputs}")
        first = self.layers[0]
        # split, not two slices: its backward joins the two gradients in one copy (a slice's pads with zeros)
        w_shared, w_items = first.weight.split([ds, self.spec.inputs - ds], dim=1)
        per_row = nn.functional.linear((shared - self.input_mean[:ds]) / self.input_std[:ds], w_shared, first.bias)
        # index_select, not per_row[rows]: its backward adds the rows' gradients in a fixed order, so training is
        # repeatable on several threads (advanced indexing's is not); the items' part is added to its copy in place
        h = per_row.index_select(0, rows).addmm_((items - self.input_mean[ds:]) / self.input_std[ds:], w_items.T)
        for layer in self.layers[1:]:  # ReLU in place: its input is no one else's
            h = h.relu_() if isinstance(layer, nn.ReLU) else layer(h)
        return h

    def normalize_targets(self, y: torch.Tensor) -> torch.Tensor:
        return (y - self.output_mean) / self.output_scale

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.normalized(x) * self.output_scale + self.output_mean

    def forward_split(self, shared: torch.Tensor, items: torch.Tensor) -> torch.Tensor:
        """forward(concat(shared[f], items[f, i])) for all f, i, without the concatenation.

        shared: (F, Ds) inputs common to every item of a frame (B(t)); items: (F, I, Di)
        per-item inputs (X_i(t)). The first layer splits into a per-frame part computed
        once per frame and a per-item part with the normalization folded into its
        weights, so removal never builds the (F, I, Ds + Di) input.
        """
        ds = shared.shape[-1]
        if ds + items.shape[-1] != self.spec.inputs:
            raise ValueError(f"inputs of sizes {ds} + {items.shape[-1]} do not add up to the network's {self.spec.inputs}")
        first = self.layers[0]
        w_shared = first.weight[:, :ds] / self.input_std[:ds]
        w_items = first.weight[:, ds:] / self.input_std[ds:]
        bias = first.bias - w_shared @ self.input_mean[:ds] - w_items @ self.input_mean[ds:]
        per_frame = shared @ w_shared.T + bias  # (F, H)
        hidden = torch.matmul(items, w_items.T)  # (F, I, H)
        hidden += per_frame[:, None, :]
        h = hidden.view(-1, hidden.shape[-1])
        for layer in self.layers[1:]:  # in place where it can: these tensors are large
            h = h.relu_() if isinstance(layer, nn.ReLU) else torch.addmm(layer.bias, h, layer.weight.T)
        h = h.mul_(self.output_scale).add_(self.output_mean)
        return h.view(items.shape[0], items.shape[1], -1)
