"""Where a model's network runs when it is applied: here in NumPy, or by torch on a GPU.

A machine without a GPU never imports torch to apply a model (facedyn.dynamics.network_weights
holds the forward pass); one with a GPU that torch can use runs the network there.
"""
from __future__ import annotations

import os
import sys

import numpy as np

NUMPY = "numpy"  # the `device` that runs the network here, in NumPy
_GPU_DRIVER_FILES = ("/dev/nvidiactl", "/proc/driver/nvidia")


def inference_device(device: str) -> str:
    """Where a model's network runs: ``numpy`` (here, without torch) or a torch device name.

    'auto' is a CUDA GPU when this machine has one that torch can use, else NumPy; the
    driver's files are looked at first, so a machine without a GPU never imports torch.
    """
    if device != "auto":
        return device
    if "torch" not in sys.modules and not any(os.path.exists(path) for path in _GPU_DRIVER_FILES):
        return NUMPY
    import torch

    return "cuda" if torch.cuda.is_available() else NUMPY


def network_runner(model, device: str, split: bool = False):
    """A model's network as a function of NumPy arrays returning one: its forward pass, or
    with `split` its forward_split (shared, items), run here in NumPy or by torch on `device`."""
    where = inference_device(device)
    if where == NUMPY:
        weights = model.weights
        return weights.forward_split if split else weights.forward
    import torch

    from facedyn.dynamics.network import resolve_device

    network = model.torch_network().to(resolve_device(where)).eval()
    dev = next(network.parameters()).device
    method = network.forward_split if split else network.forward

    def run(*arrays: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            return method(*(torch.from_numpy(np.ascontiguousarray(a)).to(dev) for a in arrays)).cpu().numpy()
    return run
