"""The shape of a dynamics network, without PyTorch.

A model file's header declares its network's shape; reading and checking it (and
`usdfacedyn inspect MODEL`, which shows it) must not pay for importing torch, so the shape
lives here and the network itself in facedyn.dynamics.network.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class NetworkSpec:
    """The shape of an MLP: input size, hidden layer sizes, output size (ReLU between)."""

    inputs: int
    hidden: tuple[int, ...]
    outputs: int

    def __post_init__(self) -> None:
        sizes = (self.inputs, *self.hidden, self.outputs)
        if any(int(s) != s or s < 1 for s in sizes):
            raise ValueError(f"network layer sizes must be positive whole numbers, got {sizes}")

    @property
    def parameter_count(self) -> int:
        """The weights and biases of its layers (the normalization statistics are not parameters)."""
        sizes = (self.inputs, *self.hidden, self.outputs)
        return sum(a * b + b for a, b in zip(sizes[:-1], sizes[1:]))

    def to_json(self) -> dict:
        return {"inputs": int(self.inputs), "hidden": [int(h) for h in self.hidden], "outputs": int(self.outputs), "activation": "relu"}

    @classmethod
    def from_json(cls, data: dict) -> "NetworkSpec":
        if data.get("activation", "relu") != "relu":
            raise ValueError(f"unsupported activation {data.get('activation')!r}; facedyn networks use relu")
        try:
            return cls(int(data["inputs"]), tuple(int(h) for h in data["hidden"]), int(data["outputs"]))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"network architecture needs inputs, hidden and outputs, got {data!r}") from exc
