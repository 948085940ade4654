"""The distance from a training target to the nearest gradient field (plasticitynet.training.gradient_floor,
issue 32): the batched conjugate-gradient solve against a dense least-squares solve, the reduction
against targets that are gradient fields (metal: the floor vanishes) and against ones that are not."""

import torch

from plasticitynet.training.gradient_floor import _diff, gradient_floor, slice_problem, solve_slices


def _dense_solution(tau, w, dx, s):
    """The same least-squares problem for slice s with an explicit difference matrix (torch.linalg.lstsq)."""
    dim = len(tau)
    n = tau[0].shape[1] + 1
    nodes = n**dim
    rows, rhs = [], []
    for axis in range(dim):
        eye = torch.eye(nodes, dtype=torch.float64).reshape(nodes, *([n] * dim))
        D = (torch.diff(eye, dim=1 + axis) / dx).reshape(nodes, -1).T  # edges x nodes
        sw = w[axis][s].reshape(-1).sqrt()
        rows.append(D * sw[:, None])
        rhs.append(tau[axis][s].reshape(-1) * sw)
    A, b = torch.cat(rows), torch.cat(rhs)
    return torch.linalg.lstsq(A, b[:, None], driver="gelsd").solution[:, 0], A, b


def test_conjugate_gradients_reach_the_least_squares_minimum():
    tau, w, dx = slice_problem("snow", 2, 6, 8, seed=7)
    phi = solve_slices(tau, w, dx, tol=1e-13)
    relative = []
    for s in range(8):
        ref, A, b = _dense_solution(tau, w, dx, s)
        residual_cg = float(((A @ phi[s].reshape(-1) - b) ** 2).sum())
        residual_ref = float(((A @ ref - b) ** 2).sum())
        norm = float((b**2).sum())
        assert abs(residual_cg - residual_ref) <= 1e-9 * norm
        # phi is defined up to a constant
        assert torch.allclose(phi[s].reshape(-1) - phi[s].mean(), ref - ref.mean(), atol=1e-8)
        relative.append(residual_ref / norm)
    # slices in the elastic region are gradient fields (residual ~0); the plastic ones are not
    assert max(relative) > 1e-4 and min(relative) < 1e-20


def test_the_solution_is_a_difference_field():
    tau, w, dx = slice_problem("sand", 3, 4, 2, seed=3)
    phi = solve_slices(tau, w, dx, tol=1e-13)
    # the residual of the normal equations vanishes: sum_i D_i^T w_i (D_i phi - tau_i) = 0
    from plasticitynet.training.gradient_floor import _diff_adjoint

    normal = sum(_diff_adjoint(w[i] * (_diff(phi, i, dx) - tau[i]), i, dx) for i in range(3))
    scale = sum(_diff_adjoint(w[i] * tau[i], i, dx).abs().max() for i in range(3))
    assert float(normal.abs().max()) <= 1e-10 * float(scale)


def test_metal_targets_are_gradient_fields():
    # von Mises with radial return is the gradient of an energy: its floor is the grid's error only
    assert gradient_floor("metal", 2, 9, 20) < 1e-8
    coarse, fine = gradient_floor("metal", 3, 5, 10), gradient_floor("metal", 3, 9, 10)
    assert fine < 1e-3 and fine < coarse


def test_non_associated_targets_have_a_floor():
    # Drucker-Prager's and Cam-Clay's return maps are not gradients: a floor well above the grid's error
    # (metal's), converged on the grid to a few percent of itself
    for material in ("sand", "snow"):
        coarse, fine = gradient_floor(material, 2, 9, 20), gradient_floor(material, 2, 17, 20)
        assert fine > 1e-3
        assert abs(fine - coarse) < 0.1 * fine
