"""The stiffening correction against a stiffening oscillator integrated in time (facedyn.dynamics.hardening)."""
import numpy as np

from facedyn.dynamics.hardening import fit_beta, fit_hardening, hardening_load, stiffen

FPS = 120.0
PAST = 60  # frames of the kernel: the oscillator below rings down within them
OMEGA = 2 * np.pi * 7.0
ZETA = 0.25


def _oscillator(acceleration: np.ndarray, beta: float, substeps: int = 20) -> np.ndarray:
    """(F, 3): x'' + 2 zeta w x' + w^2 (x + beta |x|^2 x) = -a, a held over each frame (RK4)."""
    h = 1.0 / (FPS * substeps)

    def rate(x, v, a):
        return v, -a - 2 * ZETA * OMEGA * v - OMEGA ** 2 * (x + beta * np.dot(x, x) * x)

    x, v = np.zeros(3), np.zeros(3)
    out = np.zeros((len(acceleration), 3))
    for frame, a in enumerate(acceleration):
        out[frame] = x
        for _ in range(substeps):
            k1 = rate(x, v, a)
            k2 = rate(x + h / 2 * k1[0], v + h / 2 * k1[1], a)
            k3 = rate(x + h / 2 * k2[0], v + h / 2 * k2[1], a)
            k4 = rate(x + h * k3[0], v + h * k3[1], a)
            x = x + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            v = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return out


def _kernel() -> np.ndarray:
    """(PAST + 1, 1, 3, 3): the linear oscillator's answer to a unit acceleration held over one frame."""
    impulse = np.zeros((PAST + 1, 3))
    impulse[0] = 1.0
    kernel = np.zeros((PAST + 1, 1, 3, 3))
    for axis in range(3):
        pulse = np.zeros_like(impulse)
        pulse[0, axis] = 1.0
        kernel[:, 0, :, axis] = _oscillator(pulse, 0.0)
    return kernel


def _load(frames: int, seed: int, g: float) -> np.ndarray:
    """A random acceleration (cm/s^2) that wanders over a few frames, peaking at `g`."""
    a = np.cumsum(np.random.default_rng(seed).normal(size=(frames, 3)), axis=0)
    a -= a.mean(axis=0)
    return g * a / np.abs(a).max()


def test_the_first_order_correction_answers_a_stiffening_oscillator():
    kernel = _kernel()
    assert np.abs(kernel[-1]).max() < 1e-2 * np.abs(kernel).max()  # the ring-down fits in the kernel
    acceleration = _load(480, 3, 800.0)
    linear = _oscillator(acceleration, 0.0)
    # the kernel's convolution is the linear oscillator itself (no future taps: future = 0)
    assert np.allclose(hardening_load(kernel, np.zeros((480, 1, 3)), 0), 0.0)
    beta = 0.1 / np.abs(linear).max() ** 2  # weak enough for first order, strong enough to matter
    stiff = _oscillator(acceleration, beta)
    load = hardening_load(kernel, linear[:, None, :], 0)[:, 0]
    corrected = linear + beta * OMEGA ** 2 * load
    miss_linear = np.linalg.norm(stiff - linear)
    assert miss_linear > 0.02 * np.linalg.norm(stiff)  # the stiffening matters here
    assert np.linalg.norm(stiff - corrected) < 0.35 * miss_linear
    fitted = fit_beta([(stiff - linear).ravel()], [load.ravel()])
    assert abs(fitted / (beta * OMEGA ** 2) - 1) < 0.2
    assert fitted > 0  # stiffening tissue: beta positive


def test_alternation_keeps_a_linear_tissue_linear():
    kernel = _kernel()
    acceleration = _load(480, 5, 800.0)
    linear = _oscillator(acceleration, 0.0)[:, None, :]

    def loads_of(gain):
        return [hardening_load(kernel, gain * linear, 0).reshape(len(linear), -1)]

    fit, beta = fit_hardening(lambda targets: float(np.vdot(targets[0], linear.ravel()) / np.vdot(linear, linear)),
                              loads_of, lambda gain: [gain * linear.reshape(len(linear), -1)], [linear.reshape(len(linear), -1)])
    assert abs(beta) * np.abs(loads_of(fit)[0]).max() < 1e-6 * np.abs(linear).max()
    assert abs(fit - 1.0) < 1e-6


def test_the_correction_never_outgrows_the_linear_answer():
    kernel = _kernel()
    linear = _oscillator(_load(240, 7, 800.0), 0.0)[:, None, :]
    beta = 50.0 / np.abs(linear).max() ** 2  # far beyond first order
    stiffened = stiffen(kernel, linear, 0, beta)
    correction = (stiffened - linear).reshape(len(linear), -1)
    assert np.all(np.linalg.norm(correction, axis=1) <= np.linalg.norm(linear.reshape(len(linear), -1), axis=1) * (1 + 1e-9))
    assert np.abs(correction).max() > 0
    weak = 1e-3 / np.abs(linear).max() ** 2  # within first order nothing is scaled
    assert np.allclose(stiffen(kernel, linear, 0, weak), linear + weak * hardening_load(kernel, linear, 0))


def test_tissue_that_seems_to_soften_is_answered_linearly():
    load = np.random.default_rng(1).normal(size=(50, 6))
    assert fit_beta([2.0 * load], [load]) == 2.0
    assert fit_beta([-2.0 * load], [load]) == 0.0
    assert fit_beta([load], [np.zeros_like(load)]) == 0.0
