import numpy as np
from scipy.optimize import rosen, rosen_der

from facedyn.stabilize import lbfgs


def test_runs_exactly_the_requested_iterations_and_descends():
    calls = []

    def f(x):
        calls.append(1)
        return rosen(x), rosen_der(x)

    x0 = np.full(6, -1.0)
    r = lbfgs.minimize(f, x0, 200)
    assert r.evaluations == len(calls)
    np.testing.assert_allclose(r.x, 1.0, atol=1e-5)
    for n in (1, 5, 20):
        short = lbfgs.minimize(f, x0, n)
        assert short.iterations == n and short.fun < rosen(x0)


def test_quadratic_with_known_scale_takes_about_one_evaluation_per_iteration():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(20, 20))
    h = a @ a.T + 20 * np.eye(20)
    b = rng.normal(size=20)

    def f(x):
        return 0.5 * x @ h @ x - b @ x, h @ x - b

    r = lbfgs.minimize(f, np.zeros(20), 6, scale=1.0 / 40.0)
    assert r.iterations == 6 and r.evaluations <= 6 + 2
    converged = lbfgs.minimize(f, np.zeros(20), 100, scale=1.0 / 40.0)
    np.testing.assert_allclose(converged.x, np.linalg.solve(h, b), atol=1e-6)
    assert converged.iterations < 30 and converged.evaluations < 40  # stops once f stalls
    assert r.scale is not None and r.scale > 0
