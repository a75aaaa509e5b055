"""A network's forward pass in NumPy: the torch module's, without importing torch where a model is applied."""
import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from facedyn.dynamics import inference
from facedyn.dynamics.inference import NUMPY, inference_device
from facedyn.dynamics.netspec import NetworkSpec
from facedyn.dynamics.network import Network, removal_spec
from facedyn.dynamics.network_weights import NetworkWeights


def random_network(spec: NetworkSpec) -> Network:
    """Random weights and a normalization that is far from the identity (every term of the pass matters)."""
    torch.manual_seed(1)
    network = Network(spec)
    rng = np.random.default_rng(1)
    std = rng.uniform(0.2, 3.0, spec.inputs)
    std[3] = 0.0  # a constant input: passes as 0
    network.set_normalization(rng.normal(size=spec.inputs), std, rng.normal(size=spec.outputs), 0.4)
    return network.eval()


@pytest.mark.parametrize("spec", [removal_spec(30, 9), NetworkSpec(12, (), 6), NetworkSpec(20, (16, 8, 4), 5)])
def test_the_numpy_forward_pass_is_the_torch_modules(spec):
    network = random_network(spec)
    weights = NetworkWeights.of(network)
    x = np.random.default_rng(2).normal(size=(40, spec.inputs)).astype(np.float32)
    with torch.no_grad():
        expected = network(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(weights.forward(x), expected, rtol=1e-5, atol=1e-5 * np.abs(expected).max())


def test_the_split_pass_is_the_concatenated_one():
    """F's pass with its per-frame inputs apart from its per-sample ones, as torch's forward_split."""
    network = random_network(removal_spec(30, 9))
    rng = np.random.default_rng(3)
    shared, items = rng.normal(size=(7, 30)).astype(np.float32), rng.normal(size=(7, 11, 9)).astype(np.float32)
    ours = NetworkWeights.of(network).forward_split(shared, items)
    with torch.no_grad():
        theirs = network.forward_split(torch.from_numpy(shared), torch.from_numpy(items)).numpy()
    whole = NetworkWeights.of(network).forward(np.concatenate([np.repeat(shared[:, None], 11, 1), items], -1).reshape(77, 39))
    assert ours.shape == (7, 11, 3)
    np.testing.assert_allclose(ours, theirs, rtol=1e-5, atol=1e-5 * np.abs(theirs).max())
    np.testing.assert_allclose(ours.reshape(77, 3), whole, rtol=1e-5, atol=1e-5 * np.abs(whole).max())


def test_the_torch_module_built_from_weights_holds_them_without_a_copy():
    weights = NetworkWeights.of(random_network(removal_spec(30, 9)))
    module = Network.from_weights(weights)
    for name, tensor in module.state_dict().items():
        assert np.shares_memory(tensor.numpy(), weights.state[name])


def test_missing_or_misshaped_weights_are_named():
    state = dict(NetworkWeights.of(random_network(removal_spec(30, 9))).state)
    with pytest.raises(ValueError, match=r"missing \['layers.2.bias'\]"):
        NetworkWeights(removal_spec(30, 9), {k: v for k, v in state.items() if k != "layers.2.bias"})
    state["layers.0.weight"] = state["layers.0.weight"][:, :-1]
    with pytest.raises(ValueError, match=r"layers.0.weight is \(128, 38\), its architecture needs \(128, 39\)"):
        NetworkWeights(removal_spec(30, 9), state)


def test_auto_runs_in_numpy_where_there_is_no_gpu(monkeypatch):
    monkeypatch.setattr(inference, "_GPU_DRIVER_FILES", ())
    expected = "cuda" if torch.cuda.is_available() else NUMPY  # torch is imported here: auto asks it
    assert inference_device("auto") == expected
    assert inference_device("numpy") == NUMPY and inference_device("cuda:1") == "cuda:1"


APPLY_WITHOUT_TORCH = """
import json, sys
import numpy as np
from facedyn.dynamics.modelfile import load_model
from facedyn.dynamics.removal import remove_dynamics
model = load_model(sys.argv[1])
points = np.repeat(model.face.rest_points[None], 30, 0) + np.random.default_rng(0).normal(0, 0.01, (30, model.face.point_count, 3))
_, offsets = remove_dynamics(points, None, None, model.fps, model, "numpy", device="numpy")
print(json.dumps({"torch": "torch" in sys.modules, "scipy": "scipy" in sys.modules, "offsets": offsets.tolist()}))
"""


def test_a_loaded_model_is_applied_without_importing_torch_or_scipy(tmp_path, monkeypatch):
    """Loading and applying a model (what remove and synthesize do) never pays for torch's import, nor,
    once its face's propagation is kept on disk, for SciPy's."""
    from test_modelfile import make_model

    from facedyn.dynamics.modelfile import load_model, save_model
    from facedyn.dynamics.removal import remove_dynamics

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))  # inherited by the subprocess
    path = save_model(make_model(), tmp_path / "f.removal")
    model = load_model(path)
    points = np.repeat(model.face.rest_points[None], 30, 0) + np.random.default_rng(0).normal(0, 0.01, (30, model.face.point_count, 3))
    _, by_torch = remove_dynamics(points, None, None, model.fps, model, "numpy", device="cpu")  # solves and keeps P
    assert np.abs(by_torch).max() > 0
    done = subprocess.run([sys.executable, "-c", APPLY_WITHOUT_TORCH, str(path)], capture_output=True, text=True, check=True)
    result = json.loads(done.stdout)
    assert result["torch"] is False and result["scipy"] is False
    np.testing.assert_allclose(np.array(result["offsets"], np.float32), by_torch, rtol=1e-4, atol=1e-5 * np.abs(by_torch).max())
