"""schrl.stl on NumPy arrays: values equal the CLI's, batches equal single paths,
gradients equal finite differences, errors name what is wrong, the GIL is released."""

import subprocess
import threading
import time

import numpy as np
import pytest

from schrl.stl import AfterStep, AvoidBoxes, Ball, Halfspace, Spec, SpecError

from cli import schrl_cli

SEMANTICS = ["hard", "soft:2", "lse:0.5", "soft:10,until=flat", "lse:0.5,until=recursive"]


def cli_robustness(spec, path, signals, semantics, tmp_path):
    trace = tmp_path / "trace.csv"
    np.savetxt(trace, path, delimiter=",", header=",".join(signals), comments="", fmt="%.17g")
    out = subprocess.run(
        [schrl_cli(), "robustness", "--spec", spec, "--trace", str(trace), "--semantics", semantics],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    return float(out.strip().splitlines()[-1])


@pytest.mark.parametrize("semantics", SEMANTICS)
@pytest.mark.parametrize(
    "text",
    [
        "F[0,20] (x > 1 & y < 0.5)",
        "G[2,30] (x > -2) & F[5,40] (y > 1 | x < -1)",
        "(x > 0) U[3,25] (y > 1.5)",
        "G[0,10] F[0,15] (x > 0.5)",
    ],
)
def test_values_equal_the_cli(text, semantics, tmp_path):
    rng = np.random.default_rng(7)
    path = np.cumsum(rng.normal(0, 0.3, size=(60, 2)), axis=0)
    spec = Spec(text, signals=["x", "y"])
    ours = spec.robustness(path, semantics)
    assert isinstance(ours, float)
    assert ours == pytest.approx(cli_robustness(text, path, ["x", "y"], semantics, tmp_path), abs=1e-9)


def test_a_batch_is_its_paths_one_by_one():
    rng = np.random.default_rng(1)
    batch = rng.normal(size=(17, 25, 2))
    spec = Spec("F[0,24] g & G[0,24] !wall", predicates={"g": Ball([1.0, 0.0], 0.5), "wall": Halfspace([0.0, 1.0], 2.0)})
    for semantics in SEMANTICS:
        rho = spec.robustness(batch, semantics)
        assert rho.shape == (17,) and rho.dtype == np.float64
        singles = [spec.robustness(p, semantics) for p in batch]
        np.testing.assert_allclose(rho, singles, rtol=0, atol=1e-12)
        rho_g, grad = spec.gradient(batch, semantics)
        assert grad.shape == batch.shape
        np.testing.assert_allclose(rho_g, rho, rtol=0, atol=1e-12)


@pytest.mark.parametrize("semantics", ["soft:5", "lse:0.3"])
def test_gradients_equal_finite_differences(semantics):
    rng = np.random.default_rng(3)
    path = rng.normal(size=(12, 2))
    spec = Spec("F[0,11] g & G[0,11] !box", predicates={
        "g": Ball([1.0, 1.0], 0.4),
        "box": AvoidBoxes([([0.0, 0.0], [0.3, 0.3])]),
    })
    rho, grad = spec.gradient(path, semantics)
    assert rho == pytest.approx(spec.robustness(path, semantics), abs=1e-12)
    h = 1e-6
    numeric = np.zeros_like(path)
    for i in np.ndindex(path.shape):
        up, down = path.copy(), path.copy()
        up[i] += h
        down[i] -= h
        numeric[i] = (spec.robustness(up, semantics) - spec.robustness(down, semantics)) / (2 * h)
    np.testing.assert_allclose(grad, numeric, atol=1e-5)


def test_predicates_mean_what_they_say():
    reach = Spec("F[0,2] g", predicates={"g": Ball([1.0, 0.0], 0.5)})
    path = np.array([[0.0, 0.0], [0.9, 0.0], [1.0, 0.0]])
    assert reach.robustness(path) == pytest.approx(0.5)
    # Any dtype and strides: ints, and a transposed view.
    assert reach.robustness(np.array([[0, 0], [1, 0]], dtype=np.int32)) == pytest.approx(0.5)
    assert reach.robustness(np.ascontiguousarray(path.T).T) == pytest.approx(0.5)
    trigger = Spec("G[0,4] (after -> x > 0)", signals=["x"], predicates={"after": AfterStep(3)})
    # Before step 3 the implication holds by its trigger's truth (1); from it, x decides.
    assert trigger.robustness(np.array([[-1.0], [-1.0], [-1.0], [2.0], [3.0]])) == pytest.approx(1.0)
    assert trigger.robustness(np.array([[-1.0], [-1.0], [-1.0], [-0.5], [3.0]])) == pytest.approx(-0.5)
    assert reach.state_dim == 2
    assert repr(reach).startswith("Spec(") and " g" in repr(reach)


def test_errors_name_what_is_wrong():
    with pytest.raises(SpecError, match="line 1, column 7"):
        Spec("F[1,2 a", signals=["a"])
    with pytest.raises(SpecError, match="nowhere"):
        Spec("F[0,2] nowhere", signals=["x"])
    with pytest.raises(SpecError, match="expected a schrl.stl Ball"):
        Spec("F g", predicates={"g": 3})
    spec = Spec("F[0,2] x > 0", signals=["x", "y"])
    with pytest.raises(SpecError, match="each state has 3 numbers, the spec reads 2"):
        spec.robustness(np.zeros((5, 3)))
    with pytest.raises(SpecError, match=r"expected \[T, D\] or \[B, T, D\]"):
        spec.robustness(np.zeros(5))
    with pytest.raises(SpecError, match="NaN"):
        spec.robustness(np.array([[0.0, np.nan]]))
    with pytest.raises(SpecError, match="semantics 'soft:-1'"):
        spec.robustness(np.zeros((3, 2)), "soft:-1")
    with pytest.raises(SpecError, match="radius must be > 0"):
        Ball([0.0, 0.0], -1.0)
    assert issubclass(SpecError, ValueError)


def test_the_gil_is_released_while_rust_evaluates():
    spec = Spec("G[0,400] F[0,300] (x > 0.5 | y < -0.5)", signals=["x", "y"])
    batch = np.random.default_rng(0).normal(size=(1200, 2000, 2))
    counted = [0]
    stop = threading.Event()

    def count():
        while not stop.is_set():
            counted[0] += 1

    thread = threading.Thread(target=count)
    thread.start()
    time.sleep(0.2)
    start_count, start = counted[0], time.perf_counter()
    time.sleep(0.3)
    free_rate = (counted[0] - start_count) / (time.perf_counter() - start)
    before, start = counted[0], time.perf_counter()
    spec.gradient(batch, "soft:5")
    elapsed = time.perf_counter() - start
    during = counted[0] - before
    stop.set()
    thread.join()
    assert elapsed > 0.1, f"the evaluation must take long enough to tell ({elapsed:.3f} s)"
    # Holding the GIL, the counter could only run in the switch intervals around the call.
    assert during > 0.05 * free_rate * elapsed, f"{during} counts in {elapsed:.2f} s, free rate {free_rate:.0f}/s"
